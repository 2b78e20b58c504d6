"""zerocal host: calibrate robot joint zero offsets.

    import hostpc
    dataset = hostpc.load_dataset("run/dataset.json")
    result = hostpc.fit(dataset, effects=["joint_offsets", "tool", "target"])
    print(result.parameters["joint_offsets.q2"])
    diagnosis = hostpc.diagnose(dataset, ladder=True)
    second_day = hostpc.predict(result, hostpc.load_dataset("day2/dataset.json"))

The names below are imported on first use, so `hostpc` commands start fast and can set up
the numeric libraries before numpy loads. `hostpc.fit` and `hostpc.diagnose` use one BLAS
thread for small problems (hostpc/threads.py).
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

_LAZY = {
    "load_dataset": "hostpc.dataset",
    "save_dataset": "hostpc.dataset",
    "fit": "hostpc.fitting",
    "FitResult": "hostpc.fitting",
    "predict": "hostpc.fitting.prediction",
    "diagnose": "hostpc.diagnostics",
    "Diagnosis": "hostpc.diagnostics",
}
__all__ = list(_LAZY)
_BLAS_LIMITED = ("fit", "diagnose")


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'hostpc' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name]), name)
    if name in _BLAS_LIMITED:  # one BLAS thread for small problems (hostpc/threads.py)
        from hostpc.threads import limited_for_small_problems

        value = limited_for_small_problems(value)
    globals()[name] = value
    return value
