"""What several benches share: a timer, the stereo_target fit cases, the scipy baseline,
the ``--seeds`` / ``--quick`` command line and an older commit's tree to run alongside.

Not a bench itself (no ``bench_`` prefix: ``bench/run.py`` does not run it). A bench imports
it after putting the repository root on ``sys.path`` (so ``python bench/bench_X.py`` works
from any folder, and ``bench/run.py`` finds the same module)::

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from bench.harness import median_ms
"""

from __future__ import annotations

import argparse
import subprocess
import tarfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

#: the three models of the fit benches: (name, --effects value); one dataset without frame
#: errors (tool and target known) for "offsets", one with them for the other two
FIT_CASES = (("offsets", None), ("offsets+tool+target", None), ("+geometry", "+geometry"))


def median_s(func: Callable[[], object], repeats: int, warm_up: int = 0) -> float:
    """Median wall time of ``func()`` in seconds over ``repeats`` calls, after ``warm_up``
    calls that are not timed."""
    for _ in range(warm_up):
        func()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def median_ms(func: Callable[[], object], repeats: int, warm_up: int = 1) -> float:
    """Median wall time of ``func()`` in ms over ``repeats`` calls, after ``warm_up`` calls
    that are not timed (imports, caches, the allocator)."""
    return 1e3 * median_s(func, repeats, warm_up)


def timed(func: Callable[[], Any]) -> tuple[float, Any]:
    """(wall seconds, value) of one call of ``func()``."""
    start = time.perf_counter()
    value = func()
    return time.perf_counter() - start, value


def stereo_fit_cases(n_poses: int, seed: int = 42) -> dict[str, tuple[Any, str | None]]:
    """The fit benches' datasets: name (FIT_CASES) -> (dataset, effects). ``n_poses``
    stereo_target poses of a UR5e with random zero offsets (seeded); "offsets" has tool and
    target known and error-free, the others carry random tool and target errors too."""
    from hostpc.synthesize import random_truth, synthesize_stereo_target

    truth = random_truth(np.random.default_rng(seed))
    offsets = {k: v for k, v in truth.items() if k.startswith("joint_offsets")}
    known = synthesize_stereo_target(offsets, n_samples=n_poses, seed=seed,
                                     known=("tool", "target")).dataset
    free = synthesize_stereo_target(truth, n_samples=n_poses, seed=seed).dataset
    datasets = {"offsets": known, "offsets+tool+target": free, "+geometry": free}
    return {name: (datasets[name], effects) for name, effects in FIT_CASES}


def scipy_baseline(problem: Any, free: np.ndarray) -> Callable[[], np.ndarray]:
    """A plain scipy fit of ``problem`` (a built Problem): ``least_squares(method="lm")``
    with its default 2-point finite differences on our whitened residuals (``evaluate``),
    over the parameters ``free`` (bool (P,): scipy has no gauge handling), from zero. The
    returned call gives the full parameter vector (P,), zero where not free."""
    from scipy.optimize import least_squares

    from hostpc.fitting.solver import evaluate

    index = np.flatnonzero(free)

    def residuals(v: np.ndarray) -> np.ndarray:
        x = np.zeros(problem.layout.size)
        x[index] = v
        return evaluate(problem, x, jacobian=False).whitened.ravel()

    def run() -> np.ndarray:
        x = np.zeros(problem.layout.size)
        x[index] = least_squares(residuals, np.zeros(index.size), method="lm", xtol=1e-12,
                                 ftol=1e-12).x
        return x

    return run


def seeds_argument(description: str, default: int, quick: int,
                   argv: Sequence[str] | None) -> int:
    """The number of seeds a seeded bench runs: ``--seeds N`` (``default``), or ``quick``
    with ``--quick``."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--seeds", type=int, default=default)
    parser.add_argument("--quick", action="store_true", help=f"{quick} seeds")
    args = parser.parse_args(argv)
    return quick if args.quick else int(args.seeds)


def old_tree(commit: str, folder: Path, packages: Sequence[str] = ("hostpc",)) -> Path:
    """The ``packages`` of ``commit`` unpacked under ``folder`` / old (``git archive``: no
    worktree, no change to the repository), to put first on PYTHONPATH and run interleaved
    with the current tree."""
    root = Path(__file__).resolve().parents[1]
    archive = folder / "old.tar"
    with archive.open("wb") as out:
        subprocess.run(["git", "-C", str(root), "archive", commit, *packages], stdout=out,
                       check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(folder / "old", filter="data")
    return folder / "old"
