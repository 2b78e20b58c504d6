"""Benchmark: `hostpc diagnose --ladder` on a 120-sample stereo dataset, every candidate.

Run ``python bench/bench_diagnose.py``; :func:`run` returns the figures as a dict (seconds):

- ``diagnose_s``: ``hostpc.diagnose(dataset)`` (fit, 5-fold held-out, all candidates with
  3-fold held-out RMS, the effect-agnostic search), median of ``repeats``;
- ``ladder_s``: the same with ``ladder=True`` (here: one more model checked);
- ``cli_ladder_s``, ``cli_ladder_min_s``: ``hostpc diagnose DATASET --ladder --json`` as a
  fresh process (Python start-up and imports included), median and min of ``cli_repeats``;
  the target is 0.5 s at these 120 poses (issue 17). Its import set is guarded by
  tests/hostpc/test_cli_imports.py (no scipy); ``python -X importtime -m hostpc.cli.main
  diagnose --ladder DATASET`` shows where start-up goes;
- ``report_s``: rendering the HTML report once (inline SVG; bench_report.py has its figures).

The dataset is examples/ur5e_stereo_hidden_compliance.json (compliance hidden), so the
ladder has two steps. Small dense linear algebra: on a loaded machine OpenBLAS's threads
compete; ``OPENBLAS_NUM_THREADS=1`` gives the steadiest figures.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "ur5e_stereo_hidden_compliance.json"
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness import median_s  # noqa: E402


def _times(func, repeats: int) -> list[float]:  # type: ignore[no-untyped-def]
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return times


def run(repeats: int = 3, dataset: Path = EXAMPLE, cli_repeats: int = 7) -> dict[str, float]:
    """The figures, in seconds (and the problem size)."""
    import hostpc
    from hostpc.report import render_html

    data = hostpc.load_dataset(dataset)
    hostpc.diagnose(data)  # warm-up: imports and caches
    diagnose_s = median_s(lambda: hostpc.diagnose(data), repeats)
    ladder_s = median_s(lambda: hostpc.diagnose(data, ladder=True), repeats)
    diagnosis = hostpc.diagnose(data, ladder=True)
    command = [sys.executable, "-m", "hostpc.cli.main", "diagnose", str(dataset), "--ladder",
               "--json"]
    def cli() -> None:  # exit 1: ran, and the model is not adequate (this example's start)
        if subprocess.run(command, check=False, capture_output=True,
                          cwd=ROOT).returncode not in (0, 1):
            raise RuntimeError(f"{' '.join(command)} failed")

    cli_times = _times(cli, cli_repeats)
    with tempfile.TemporaryDirectory():
        start = time.perf_counter()
        render_html(diagnosis)
        report_s = time.perf_counter() - start
    return {
        "n_samples": float(data.n_samples),
        "n_candidates": float(len(diagnosis.candidates)),
        "ladder_steps": float(len(diagnosis.ladder or ())),
        "diagnose_s": diagnose_s,
        "ladder_s": ladder_s,
        "cli_ladder_s": float(statistics.median(cli_times)),
        "cli_ladder_min_s": min(cli_times),
        "report_s": report_s,
    }


if __name__ == "__main__":
    for name, value in run().items():
        print(f"{name:>14}: {value:.3f}")
