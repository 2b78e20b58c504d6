"""BLAS threads limited for small problems inside the library (hostpc.threads)."""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_info

import hostpc
from hostpc.threads import SMALL_PROBLEM_SAMPLES, blas_threads_for


def _blas_threads() -> list[int]:
    np.linalg.svd(np.ones((4, 3)))  # make sure the BLAS is loaded
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_small_problems_run_on_one_blas_thread_and_the_setting_is_restored() -> None:
    before = _blas_threads()
    with blas_threads_for(120):
        assert _blas_threads() and all(n == 1 for n in _blas_threads())
    assert _blas_threads() == before
    with blas_threads_for(SMALL_PROBLEM_SAMPLES + 1), blas_threads_for(None):
        assert _blas_threads() == before  # large or unknown: the user's setting


def test_public_fit_and_diagnose_are_the_limited_library_functions() -> None:
    from hostpc.diagnostics import diagnose
    from hostpc.fitting import fit

    assert hostpc.fit.__wrapped__ is fit  # type: ignore[attr-defined]
    assert hostpc.diagnose.__wrapped__ is diagnose  # type: ignore[attr-defined]
