"""BLAS threads for small problems: one thread where more only cost time.

A calibration problem is tall and thin (3 rows a pose, tens of parameters): its SVDs and
products are far too small to gain from BLAS threads, and on a loaded machine the threads
fight for the cores (a 120-pose `numpy.linalg.svd` took 72 ms under load with the default
threads against well under 1 ms with one). The CLI sets the thread variables before numpy
loads; the Python API cannot (numpy is usually loaded already), so `hostpc.fit` and
`hostpc.diagnose` run inside `blas_threads_for(n_samples)`, which limits the BLAS of the
running process to one thread for problems up to `SMALL_PROBLEM_SAMPLES` samples, through
threadpoolctl (it finds the BLAS libraries numpy and scipy loaded and sets their thread
count; the previous count is restored on exit). Larger problems keep the user's setting.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

SMALL_PROBLEM_SAMPLES = 20_000

_controller: Any = None
F = TypeVar("F", bound=Callable[..., Any])


def _blas_controller() -> Any:
    """threadpoolctl's controller, built once (it scans the loaded libraries), or None if
    threadpoolctl is not installed."""
    global _controller
    if _controller is None:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # an optional speed-up: without it nothing is limited
            _controller = False
        else:
            _controller = ThreadpoolController()
    return _controller or None


@contextlib.contextmanager
def blas_threads_for(n_samples: int | None) -> Iterator[None]:
    """One BLAS thread inside the block if the problem has at most SMALL_PROBLEM_SAMPLES
    samples (None: unknown, nothing limited)."""
    controller = (_blas_controller()
                  if n_samples is not None and n_samples <= SMALL_PROBLEM_SAMPLES else None)
    if controller is None:
        yield
        return
    with controller.limit(limits=1, user_api="blas"):
        yield


def limited_for_small_problems(func: F) -> F:
    """`func(dataset, ...)` run inside `blas_threads_for(dataset.n_samples)`."""

    @functools.wraps(func)
    def wrapper(dataset: Any, *args: Any, **kwargs: Any) -> Any:
        with blas_threads_for(getattr(dataset, "n_samples", None)):
            return func(dataset, *args, **kwargs)

    return wrapper  # type: ignore[return-value]
