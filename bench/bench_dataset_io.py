"""Benchmark: reading and writing datasets of every built-in kind, in N (issue 17).

    /work/venv/bin/python bench/bench_dataset_io.py            # N = 1k, 10k, 100k
    /work/venv/bin/python bench/bench_dataset_io.py --quick    # N = 1k, 10k

Per kind and N: a file of N samples (the kind's example samples repeated), then, medians of
``repeats`` (interleaved): a bare ``json.load`` of it; ``hostpc.load_dataset`` (the column
reader where the kind has one); ``save_dataset`` of the loaded dataset (the column writer);
and, up to 10k samples, the same load and save forced sample by sample (the column paths
off), which is what a kind without column paths costs. sphere_probe's example has
``group`` fields, which its column reader declines: its load is the sample-by-sample one.
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bench.harness import median_s  # noqa: E402

KINDS = ("stereo_target", "sphere_probe", "dual_loop", "world_point", "world_pose")
SIZES = (1_000, 10_000, 100_000)


def _document(method: str, n: int) -> dict[str, Any]:
    import numpy as np

    from hostpc.dataset.writing import dataset_to_dict
    from hostpc.model.measurements.registry import measurement_model

    doc = dataset_to_dict(measurement_model(method).example(np.random.default_rng(1)))
    samples = doc["samples"]
    doc["samples"] = [samples[i % len(samples)] for i in range(n)]
    return doc


def run(sizes: tuple[int, ...] = SIZES, kinds: tuple[str, ...] = KINDS,
        repeats: int = 3) -> list[dict[str, Any]]:
    import hostpc
    from hostpc.dataset import reading, save_dataset, writing

    rows = []
    for method in kinds:
        for n in sizes:
            with tempfile.TemporaryDirectory() as tmp:
                path = Path(tmp) / "d.json"
                path.write_text(json.dumps(_document(method, n)))
                dataset = hostpc.load_dataset(path)
                out = Path(tmp) / "out.json"
                row: dict[str, Any] = {"kind": method, "n": n}
                row["json_load_s"] = median_s(lambda p=path: json.loads(p.read_text()), repeats)
                row["load_s"] = median_s(lambda p=path: hostpc.load_dataset(p), repeats)
                row["save_s"] = median_s(lambda d=dataset, o=out: save_dataset(d, o), repeats)
                if n <= 10_000:
                    columnar, writes = reading._columnar_dataset, writing._writes_columns
                    try:
                        reading._columnar_dataset = lambda *args: None  # type: ignore[assignment]
                        writing._writes_columns = lambda cls: False  # type: ignore[assignment]
                        row["load_by_sample_s"] = median_s(
                            lambda p=path: hostpc.load_dataset(p), repeats)
                        row["save_by_sample_s"] = median_s(
                            lambda d=dataset, o=out: save_dataset(d, o), repeats)
                    finally:
                        reading._columnar_dataset = columnar  # type: ignore[assignment]
                        writing._writes_columns = writes  # type: ignore[assignment]
                rows.append(row)
                print(json.dumps(row), file=sys.stderr, flush=True)
    return rows


def print_table(rows: list[dict[str, Any]]) -> None:
    print(f"{'kind':<14} {'N':>7} {'json.load':>9} {'load':>7} {'ratio':>6} {'save':>7} "
          f"{'load 1by1':>9} {'save 1by1':>9}   (s, medians)")
    def cell(r: dict[str, Any], key: str, width: int) -> str:
        return f"{r[key]:>{width}.3f}" if key in r else f"{'-':>{width}}"

    for r in rows:
        print(f"{r['kind']:<14} {r['n']:>7} {cell(r, 'json_load_s', 9)} {cell(r, 'load_s', 7)} "
              f"{r['load_s'] / r['json_load_s']:>5.1f}x {cell(r, 'save_s', 7)} "
              f"{cell(r, 'load_by_sample_s', 9)} {cell(r, 'save_by_sample_s', 9)}")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    sizes = tuple(n for n in SIZES if "--quick" not in argv or n <= 10_000)
    print_table(run(sizes))
    return 0


if __name__ == "__main__":
    sys.exit(main())
