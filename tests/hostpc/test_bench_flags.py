"""bench/run.py hands a flag such as ``--quick`` only to a bench whose file mentions it (a
bench's ``main(argv)`` knows its own flags). A bench that parses its command line with
bench.harness.seeds_argument (``--seeds N`` / ``--quick``) must therefore name ``--quick``
in its own text, its usage line, or ``run.py NAME --quick`` runs the full seed count."""

from __future__ import annotations

from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
SEEDED = sorted(p for p in BENCH.glob("bench_*.py") if "seeds_argument(" in p.read_text())


def test_the_seeded_benches_are_found() -> None:
    assert {p.stem for p in SEEDED} >= {"bench_diagnose_null", "bench_diagnose_multi"}


@pytest.mark.parametrize("path", SEEDED, ids=lambda p: p.stem)
def test_a_seeded_bench_names_quick_so_run_py_passes_it(path: Path) -> None:
    usage = path.read_text().split('"""')[1]
    assert "[--quick]" in usage
