"""Benchmark: the HTML report (issue 17: "the report in well under a second").

Run ``/work/venv/bin/python bench/bench_report.py`` (or ``bench/run.py report``);
:func:`run` returns the figures (seconds, kB):

- ``render_diagnosis_s``: ``render_html(diagnosis)``, the report of a diagnosis with its
  ladder (8 figures), median of ``repeats``;
- ``render_calibration_s``: ``render_calibration_html(result, diagnosis, truth)``, the
  report a calibration run writes (result tables, then the same diagnosis);
- ``diagnose_s``: ``hostpc.diagnose(dataset)`` as the runner calls it before rendering (the
  rest of the "report" stage of ``hostpc calibrate``);
- ``html_kB``: the calibration report's size;
- ``import_s``: ``import hostpc.report`` in a fresh process (the figures need no
  matplotlib any more);
each at 120 samples (the example dataset) and at 5000 synthetic samples (scatter plots
thinned to 1500 points; the diagnosis there without held-out folds and search, which only
the report's inputs need).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "ur5e_stereo_hidden_compliance.json"
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness import median_s  # noqa: E402


def result_document(fit: Any) -> dict[str, Any]:
    """A result document shaped like hostpc.calibrate.summary's, from a fit."""
    joints = []
    for j, name in enumerate(n for n in fit.names if n.startswith("joint_offsets.")):
        p = fit.parameters[name]
        correction = None if p.fixed else math.degrees(p.value)
        joints.append({"joint": j + 1, "label": f"q{j + 1}", "old_deg": 0.0,
                       "correction_deg": correction,
                       "sigma_deg": None if p.fixed else math.degrees(p.std),
                       "new_deg": correction or 0.0, "pushed": not p.fixed,
                       "note": "unidentifiable" if p.fixed else ""})
    return {"method": fit.problem.method, "robot": {"name": "ur5e", "sim": True},
            "run_dir": "/bench/run", "known": [], "offsets": {"joints": joints},
            "push": {"status": "pushed", "rollback_id": "rb-1"},
            "verify": {"verdict": "PASS", "statistic": 27.1, "dof": 30, "p_value": 0.62,
                       "alpha": 0.01, "rms_mm": 0.021, "tolerance_mm": None, "n_poses": 10,
                       "pushed": True},
            "exit_code": 0}


def _case(data: Any, repeats: int, **options: Any) -> dict[str, float]:
    import hostpc
    from hostpc.report import render_calibration_html, render_html

    diagnose_s = median_s(lambda: hostpc.diagnose(data, **options), 1)
    diagnosis = hostpc.diagnose(data, **options)
    truth = {"zero_errors": [0.0] * 6, "effects": {"joint_compliance": [0.0] * 6}}
    document = result_document(diagnosis.fit)
    render_html(diagnosis)  # warm-up
    html = render_calibration_html(document, diagnosis, truth)
    return {
        "n_samples": float(data.n_samples),
        "diagnose_s": diagnose_s,
        "render_diagnosis_s": median_s(lambda: render_html(diagnosis), repeats),
        "render_calibration_s": median_s(
            lambda: render_calibration_html(document, diagnosis, truth), repeats),
        "html_kB": len(html.encode("utf-8")) / 1e3,
    }


def run(repeats: int = 5) -> dict[str, dict[str, float]]:
    """The figures per dataset size."""
    import hostpc
    from hostpc.synthesize import random_truth, synthesize_stereo_target

    small = hostpc.load_dataset(EXAMPLE)
    large = synthesize_stereo_target(random_truth(np.random.default_rng(7)), seed=7,
                                     n_samples=5000).dataset
    command = [sys.executable, "-c", "import hostpc.report"]
    import_s = median_s(lambda: subprocess.run(command, check=True, cwd=ROOT), 3)
    base = [sys.executable, "-c", "import hostpc.diagnostics"]
    import_base_s = median_s(lambda: subprocess.run(base, check=True, cwd=ROOT), 3)
    return {
        "120 samples, ladder": _case(small, repeats, ladder=True),
        "5000 samples": _case(large, 3, cv_folds=0, rank_cv_folds=0, interactions=False),
        "imports": {"import_s": import_s,
                    "import_report_beyond_diagnostics_s": import_s - import_base_s},
    }


def main() -> int:
    for case, figures in run().items():
        print(case)
        for name, value in figures.items():
            print(f"  {name:>36}: {value:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
