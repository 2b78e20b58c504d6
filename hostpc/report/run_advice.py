"""The diagnosis's advice sized to what a calibration run is for.

`hostpc diagnose` judges a model, and for that a short plan's samples are too few (the
advice says "too few samples to judge reliably ... measure at least N"). A calibration run
measures the fewest poses that reach its target sigma and then checks the offsets on fresh
poses: when that check passed, the run did what it is for, and its report says so; what is
too few is the data for a *diagnosis*, and the report gives the exact command that measures
enough of it (a run of its own that pushes nothing, then `hostpc diagnose --ladder`).

    from hostpc.report.run_advice import run_advice
    advice = run_advice(diagnosis, result_document)   # tuple of sentences
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from hostpc.dataset.kind_registry import DEFAULT_METHOD
from hostpc.diagnostics import Diagnosis
from hostpc.diagnostics.advice import few_samples_problems, few_samples_sentence, needed_samples

Document = Mapping[str, Any]

#: the measurement method a calibration uses without --method


def _passed(result: Document) -> tuple[bool, bool, int]:
    """(the run's fresh-pose check passed, it checked pushed offsets, fresh poses)."""
    verify = result.get("verify") or {}
    verdict = str(verify.get("verdict", "")).upper()
    passed = verdict == "PASS" if verdict else bool(verify.get("passed"))
    pushed = bool(verify.get("pushed", (result.get("push") or {}).get("status") == "pushed"))
    return passed, pushed, int(verify.get("n_measured") or verify.get("n_poses") or 0)


def diagnosis_commands(result: Document, n_poses: int) -> tuple[str, str]:
    """(the calibrate command that measures ``n_poses`` fit poses for a diagnosis and pushes
    nothing, the diagnose command of its dataset), for the robot, method, known frames, rig
    and model of the run in ``result``."""
    robot = result.get("robot") or {}
    settings = result.get("settings") or {}
    run_dir = str(result.get("run_dir") or "RUN")
    out = f"{run_dir.rstrip('/')}-diagnosis"
    parts = ["hostpc", "calibrate"]
    if robot.get("sim"):
        parts += ["--robot", "sim"]
        if robot.get("scenario"):
            parts += ["--scenario", str(robot["scenario"])]
    else:
        parts += ["--robot", str(robot.get("address") or "HOST")]
        if robot.get("driver") not in (None, "zerocal"):
            parts += ["--driver", str(robot["driver"])]
    method = result.get("method") or DEFAULT_METHOD
    if method != DEFAULT_METHOD:
        parts += ["--method", str(method)]
    if result.get("known"):
        parts += ["--known", ",".join(result["known"])]
    rig = ((result.get("method_setup") or {}).get("rig") or {}).get("file")
    if rig and Path(rig).is_file():
        parts += ["--rig", str(rig)]
    if settings.get("effects"):
        parts += ["--effects", str(settings["effects"])]
    for plugin in settings.get("plugins") or []:
        parts += ["--plugin", str(plugin)]
    parts += ["--poses", str(n_poses), "--no-push", "--out", out]
    diagnose = ["hostpc", "diagnose", f"{out}/dataset.json", "--ladder"]
    return shlex.join(parts), shlex.join(diagnose)


def run_advice(diagnosis: Diagnosis, result: Document) -> tuple[str, ...]:
    """The advice of ``diagnosis`` for the report of the run whose result document is
    ``result``: its "too few samples to judge" sentence replaced, when the run's fresh-pose
    check passed, by what the run showed and what a diagnosis would need (the commands);
    otherwise the advice unchanged."""
    advice = diagnosis.advice
    check = diagnosis.check
    few = few_samples_sentence(check)
    passed, pushed, n_fresh = _passed(result)
    if few is None or few not in advice or not passed or check.adequacy.dof <= 0:
        return advice
    n_samples = check.fit.residuals_raw.shape[0]
    needed = needed_samples(check)
    measure, diagnose = diagnosis_commands(result, needed)
    shown = (f"the pushed offsets verified on {n_fresh} fresh poses" if pushed
             else f"the fitted model explained {n_fresh} fresh poses (a model check: nothing "
                  f"was pushed)")
    sized = (f"Enough samples for a calibration: {n_samples} samples fitted the offsets and "
             f"{shown}. For a diagnosis of the model they are few: "
             f"{'; '.join(few_samples_problems(check))}. A diagnosis needs at least "
             f"{needed} samples: `{measure}`, then `{diagnose}`.")
    return tuple(sized if sentence == few else sentence for sentence in advice)
