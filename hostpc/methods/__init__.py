"""Measurement methods and the shared calibration procedure.

A method is one module with one `hostpc.methods.base.Method` subclass (plan candidates,
acquire one sample per pose, build the dataset); `hostpc.calibrate.runner` runs every method
through the same procedure (journal, resume, planning, fit, guarded push, verify, report).
A new method registers here by name -> "module:Class" (imported on first use).
"""

from __future__ import annotations

import importlib

from hostpc.errors import InputError
from hostpc.methods.base import Method

METHOD_CLASSES: dict[str, str] = {
    "stereo_target": "hostpc.methods.stereo_target:StereoTargetMethod",
    "sphere_probe": "hostpc.methods.sphere_probe.method:SphereProbeMethod",
    "dual_loop": "hostpc.methods.dual_loop:DualLoopMethod",
    "world_point": "hostpc.methods.world_point:WorldPointMethod",
}


def method_class(name: str) -> type[Method]:
    """The Method class registered as `name`; InputError if unknown or not built yet."""
    spec = METHOD_CLASSES.get(name)
    if spec is None:
        raise InputError(f"--method {name!r}: unknown (known: {', '.join(METHOD_CLASSES)})")
    module_name, _, class_name = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name == module_name:
            raise InputError(f"--method {name!r} is not available in this build") from None
        raise
    cls: type[Method] = getattr(module, class_name)
    return cls


__all__ = ["METHOD_CLASSES", "Method", "method_class"]
