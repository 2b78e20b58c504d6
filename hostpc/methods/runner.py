"""The calibration procedure every method shares (`hostpc calibrate`).

    S1  read the controller's state and zero offsets (a resume checks they did not change)
        and build the nominal cell (controller description, --cell, --known)
    --  method.prepare (e.g. the stereo rig), persisted in the run folder
    --  plan: candidate pool -> informative poses (planning.py) + verification poses;
        identifiability check of the plan BEFORE moving; the plan, seed and settings go
        into run.json
    S2  acquire: one journaled sample per pose (journal.py); a resume skips what is there
    S3  dataset.json (zerocal-dataset/1) from the measured fit poses
    S4  fit (fit.json)
    S5  guarded push (push.py): old/new shown, limit, unidentifiable joints kept
    --  verify (verify.py): fresh poses after the push, before vs after, pass/fail
    --  result.json, summary.txt (summary.py) and, if the diagnostics/report packages
        exist, report.html

A resume (resume.py) checks the controller's offsets, settles a push cut short and keeps
sample time continuing.

The runner talks to the robot only through `RobotAdapter` and to the method only through
`Method`. Truth (simulation only) comes from a callable, read at S1, before any push.
Exit codes beyond hostpc.errors: 5 = push refused by a guard rail, 6 = verification of the
pushed offsets failed (with nothing pushed the verification is a model check: reported only).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.dataset import Dataset, dataset_from_dict, save_dataset
from hostpc.errors import ConnectionFailed, ControllerError, InputError, ZerocalError
from hostpc.fitting import FitResult, fit
from hostpc.methods import method_class
from hostpc.methods.base import Method, NullProgress, Plan, Progress, RunSettings
from hostpc.methods.cell import build_cell, cell_from_dict
from hostpc.methods.journal import Journal, write_json_atomic
from hostpc.methods.planning import (
    check_plan,
    design_matrix,
    joint_offset_sigmas,
    make_design,
    order_for_travel,
    poses_for_target_sigma,
    select,
    select_groups,
    verify_groups,
)
from hostpc.methods.push import PushPlan, execute_push, plan_push
from hostpc.methods.resume import (
    CLOCK_TOLERANCE_S,
    RESUME_OVERRIDABLE,
    SampleClock,
    check_resume_offsets,
    journaled_push,
    resume_settings,
    settle_push_intent,
)
from hostpc.methods.robot_time import RobotTimer
from hostpc.methods.summary import (
    EXIT_PUSH_REFUSED,
    EXIT_VERIFY_FAILED,
    RESULT_FORMAT,
    finite_or_none,
    format_summary,
    result_document,
    truth_comparison,
)
from hostpc.methods.verify import VerifyResult, evaluate_verify
from hostpc.robots.base import RobotAdapter, RobotState

__all__ = [
    "CLOCK_TOLERANCE_S", "EXIT_PUSH_REFUSED", "EXIT_VERIFY_FAILED", "RESULT_FORMAT",
    "RESUME_OVERRIDABLE", "PlanningError", "RobotInfo", "RunOutcome", "Runner",
    "format_summary", "truth_comparison",
]

class PlanningError(InputError):
    """The planned poses cannot separate the model's parameters (or none are reachable)."""


@dataclass(frozen=True)
class RobotInfo:
    """How the run reaches its robot: the address text, the driver, simulated or not, and
    the simulated scenario file (for a resume of a simulated run)."""

    address: str
    driver: str = "zerocal"
    sim: bool = False
    scenario: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"address": self.address, "driver": self.driver, "sim": self.sim,
                "scenario": self.scenario}


@dataclass
class RunOutcome:
    """What a run produced. document: the JSON result; summary: the human text."""

    run_dir: Path
    document: dict[str, Any]
    summary: str
    exit_code: int
    fit: FitResult | None = None
    dataset: Dataset | None = None
    verify: VerifyResult | None = None
    push: PushPlan | None = None
    extras: dict[str, Any] = field(default_factory=dict)


class Runner:
    """One calibration run in `run_dir` (new, or resumed if the folder holds a run).

    settings / cell_file / known / default_known are used for a new run only; a resume
    reads them from run.json. truth: simulation only, returns the simulator's truth dict.
    """

    def __init__(
        self,
        robot: RobotAdapter,
        run_dir: str | Path,
        *,
        robot_info: RobotInfo,
        settings: RunSettings | None = None,
        cell_file: Mapping[str, Any] | None = None,
        known: tuple[str, ...] | None = None,
        default_known: tuple[str, ...] = (),
        progress: Progress | None = None,
        truth: Callable[[], dict[str, Any]] | None = None,
        report: bool = True,
        resume_overrides: Mapping[str, Any] | None = None,
    ) -> None:
        self.robot = robot
        self.run_dir = Path(run_dir)
        self.robot_info = robot_info
        self.settings = settings
        self.cell_file = cell_file
        self.known = known
        self.default_known = default_known
        self.progress: Progress = progress or NullProgress()
        self.truth_reader = truth
        self.report = report
        self.resume_overrides = dict(resume_overrides or {})
        self.journal = Journal(self.run_dir)
        self.header: dict[str, Any] = {}
        self._clock = SampleClock(self.journal, self.progress)  # resume: sample t continues

    # ------------------------------------------------------------------ top level

    async def run(self) -> RunOutcome:
        """Run (or resume) the whole procedure; see the module docstring."""
        resume = self.journal.exists
        try:
            return await self._run(resume)
        except ConnectionFailed as exc:
            raise ConnectionFailed(f"{exc}; {self._journaled()} continue with: hostpc "
                                   f"calibrate --resume {self.run_dir}") from exc
        except ControllerError as exc:
            if not self.journal.exists:
                raise
            raise type(exc)(f"{exc}; {self._journaled()} continue with: hostpc calibrate "
                            f"--resume {self.run_dir}") from exc

    def _journaled(self) -> str:
        if not self.journal.exists:
            return "nothing measured yet;"
        n = len(self.journal.records("fit")) + len(self.journal.records("verify"))
        return f"{n} poses journaled in {self.run_dir};"

    async def _run(self, resume: bool) -> RunOutcome:
        progress = self.progress
        progress.stage("read controller")
        state = await self.robot.state()
        offsets = np.asarray(await self.robot.get_offsets(), float)
        truth = self.truth_reader() if self.truth_reader is not None else None

        if resume:
            self.header = self.journal.read_header()
            self.journal.load()
            settings = resume_settings(RunSettings.from_dict(self.header["settings"]),
                                       self.resume_overrides, self.journal, progress)
            cell = cell_from_dict(self.header["cell"])
            initial = self.header["initial"]
            check_resume_offsets(self.journal, self.run_dir,
                                 np.asarray(initial["zero_offsets"], float), offsets)
            self._clock.last_t = self.journal.last_sample_t()
            progress.message(f"resuming {self.run_dir}: "
                             f"{len(self.journal.records('fit'))} fit and "
                             f"{len(self.journal.records('verify'))} verify poses journaled")
        else:
            if self.settings is None:
                raise InputError("a new run needs settings")
            settings = self.settings
            cell = build_cell(state.camera, state.robot, self.cell_file, self.known,
                              self.default_known)
            initial = _state_dict(state, offsets)
            self.header = {
                "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
                "robot": self.robot_info.to_dict(),
                "settings": settings.to_dict(),
                "seed": settings.seed,
                "cell": cell.to_dict(),
                "initial": initial,
            }
            self.journal.write_header(self.header)

        method = method_class(settings.method)(settings, cell, self.run_dir)
        if hasattr(method, "set_time_origin"):
            method.set_time_origin(self._clock.time_origin(initial, state))
        if settings.effects is None and method.default_effects() is not None:
            # the method's own default model (sphere_probe: + trigger_latency)
            settings = dataclasses.replace(settings, effects=method.default_effects())
        method.check_inputs()
        timer = RobotTimer(self.robot, self.journal, state)  # robot time (robot_time.py)
        await method.prepare(self.robot, progress)
        await timer.end("rig")

        if "plan" in self.header:
            plan = Plan.from_dict(self.header["plan"])
        else:
            plan = self._plan(method, state, settings)
            self.header["plan"] = plan.to_dict()
            self.journal.write_header(self.header)
        for text in plan.info.get("structural_unidentifiable", []):
            progress.message(f"note: {text}")

        q_from = self.journal.last_q()
        q_now = np.asarray(q_from, float) if q_from is not None else state.q
        timer.begin()
        q_now = await self._acquire(method, "fit", plan.q, q_now)
        await timer.end("measure")

        dataset = self._dataset(method, "fit")
        if dataset.n_samples < 3:
            raise ZerocalError(f"only {dataset.n_samples} of {plan.q.shape[0]} poses measured; "
                               "nothing to fit (see the skipped reasons in journal.jsonl)")
        save_dataset(dataset, self.run_dir / "dataset.json")

        progress.stage("fit")
        result = fit(dataset, settings.effects, plugins=settings.plugins, loss=settings.loss,
                     cv_folds=settings.cv_folds)
        write_json_atomic(self.run_dir / "fit.json", result.to_dict())
        status = "converged" if result.converged else "NOT converged"
        progress.message(f"fit: RMS {result.rms * 1e3:.4f} mm, chi2/dof "
                         f"{result.chi2_dof:.3f}, {status}")

        initial_offsets = np.asarray(initial["zero_offsets"], float)
        push_plan = plan_push(result, initial_offsets, settings.max_correction_deg,
                              settings.force, dataset_file=str(self.run_dir / "dataset.json"))
        push_status, pushed_delta = await self._push(push_plan, settings, offsets)
        exports = self._export_offsets(cell.robot, push_plan, push_status)

        verify_result: VerifyResult | None = None
        if settings.n_verify > 0 and plan.q_verify.shape[0] > 0:
            timer.begin()
            await self._acquire(method, "verify", plan.q_verify, q_now)
            await timer.end("verify")
            verify_dataset = self._dataset(method, "verify")
            if verify_dataset.n_samples > 0:
                save_dataset(verify_dataset, self.run_dir / "verify_dataset.json")
                verify_result = evaluate_verify(result, verify_dataset, pushed_delta,
                                                plan.q_verify.shape[0],
                                                settings.verify_factor)
                write_json_atomic(self.run_dir / "verify.json", verify_result.to_dict())

        document = result_document(self.journal, self.run_dir, self.robot_info.to_dict(),
                                   settings, cell, plan, method, dataset, result, push_plan,
                                   push_status, verify_result, truth)
        if exports is not None:  # the robot keeps no offsets (UR): these files are the push
            document["push"].update(on_controller=False, exports=exports)
            document["files"].update({f"ur_{kind}": path for kind, path in exports.items()})
        summary = format_summary(document)
        (self.run_dir / "summary.txt").write_text(summary + "\n", encoding="utf-8")
        if self.report:
            report_file = self._write_report(dataset, settings, document, truth)
            if report_file:
                document["files"]["report"] = report_file
        write_json_atomic(self.run_dir / "result.json", document)
        progress.close()
        return RunOutcome(self.run_dir, document, summary, document["exit_code"], result,
                          dataset, verify_result, push_plan)

    # ------------------------------------------------------------------ steps

    def _plan(self, method: Method, state: RobotState, settings: RunSettings) -> Plan:
        """Candidate pool, informative selection, order, verification poses, check."""
        progress = self.progress
        progress.stage("plan")
        rng = np.random.default_rng(settings.seed)
        pool = method.candidates(state, rng)
        needed = settings.n_poses + settings.n_verify
        if pool.shape[0] < max(needed, 1):
            raise PlanningError(
                f"only {pool.shape[0]} reachable poses see the target (need {needed}); check "
                "the cell (target position, camera mount) and the joint limits")
        A, names, units = design_matrix(method.design_dataset(pool), settings.effects,
                                        settings.plugins)
        design = make_design(A, names, units)
        structural = design.structural
        groups = method.pose_groups(pool)
        if groups is None:
            chosen = select(design, settings.n_poses, settings.criterion, rng)
            if settings.target_sigma_deg is not None:  # the fewest poses that reach it
                needed = poses_for_target_sigma(design, chosen,
                                                math.radians(settings.target_sigma_deg),
                                                state.q.size, min_poses=3)
                chosen = chosen if needed is None else chosen[:needed]
            fit_indices = chosen[order_for_travel(pool[chosen], state.q,
                                                  tour=settings.target_sigma_deg is not None)]
        else:  # whole groups (sphere_probe: an orientation's 5 contacts), in the pool order
            fit_indices = select_groups(design, groups, settings.n_poses, settings.criterion,
                                        rng)
        plan_design = design.subset(fit_indices)
        check = check_plan(plan_design)
        if not check.ok:
            lines = "; ".join(d.description for d in check.deficient)
            raise PlanningError(
                f"the {len(fit_indices)} planned poses cannot separate the model's parameters "
                f"(rank {check.plan_rank} of {check.pool_rank}): {lines}. Fix: more poses "
                "(--poses), fewer effects (--effects), or a wider pose range")
        q_fit = pool[fit_indices]
        last = q_fit[-1] if q_fit.shape[0] else state.q
        if groups is None:
            rest = np.setdiff1d(np.arange(pool.shape[0]), fit_indices)
            verify_indices = rng.choice(rest, size=min(settings.n_verify, rest.size),
                                        replace=False)
            verify_indices = verify_indices[order_for_travel(pool[verify_indices], last)]
        else:
            verify_indices = verify_groups(groups, fit_indices, settings.n_verify, rng)
        q_verify = pool[verify_indices]
        sigmas = joint_offset_sigmas(plan_design, state.q.size)
        info = {
            "criterion": settings.criterion,
            "target_sigma_deg": settings.target_sigma_deg,
            "n_candidates": int(pool.shape[0]),
            "parameters": list(names),
            "predicted_joint_sigma_deg": [None if not np.isfinite(s) else math.degrees(s)
                                          for s in sigmas],
            "structural_unidentifiable": [d.description for d in structural],
            "structural_fixed": [d.fixed for d in structural],
        }
        progress.message(
            f"plan: {len(fit_indices)} poses from {pool.shape[0]} candidates "
            f"({settings.criterion}-optimal), {q_verify.shape[0]} verification poses; "
            "predicted joint offset sigma "
            + ", ".join("-" if not np.isfinite(s) else f"{math.degrees(s):.4f}"
                        for s in sigmas) + " deg")
        return Plan(q=q_fit, q_verify=q_verify, info=info)

    async def _acquire(self, method: Method, phase: str, q_plan: np.ndarray,
                       q_now: np.ndarray) -> np.ndarray:
        """Measure every planned pose of `phase` not yet journaled; returns where the
        robot is."""
        progress = self.progress
        total = q_plan.shape[0]
        progress.stage("measure" if phase == "fit" else "verify", total)
        done = len(self.journal.records(phase))
        progress.advance(done)
        for index in range(total):
            if self.journal.has(phase, index):
                continue
            record = await method.acquire(self.robot, phase, index, q_plan[index], q_now)  # type: ignore[arg-type]
            record = self._clock.continue_t(record)
            self.journal.record(record)
            if record.q_end is not None:
                q_now = np.asarray(record.q_end, float)
            done += 1
            if not record.ok:
                progress.message(f"{phase} pose {index}: skipped ({record.reason})")
            progress.advance(done, f"{phase} pose {index + 1}/{total}")
        return q_now

    def _dataset(self, method: Method, phase: str) -> Dataset:
        samples = [r.sample for r in self.journal.records(phase) if r.ok and r.sample]
        return dataset_from_dict(method.dataset_document(samples))  # type: ignore[arg-type]

    async def _push(self, plan: PushPlan, settings: RunSettings, offsets_now: np.ndarray
                    ) -> tuple[str, np.ndarray]:
        """Push (or not); returns (status, the delta now inside the controller).

        On a resume: a push cut short (intent journaled, no result) is settled from the
        controller's offsets; a journaled push whose offsets are in the controller is
        "pushed"; one the controller no longer has (rolled back) is not repeated unless the
        resume asks for it (--push or --force): "rolled_back"."""
        progress = self.progress
        settle_push_intent(self.journal, self.run_dir, self.robot_info.address, progress,
                           offsets_now)
        zero = np.zeros_like(plan.old)
        journaled = journaled_push(self.journal, self.run_dir, progress, offsets_now,
                                   self._push_asked(), zero)
        if journaled is not None:
            return journaled
        if not settings.push:
            return "disabled", zero
        if plan.refused:
            progress.message(f"push refused: {plan.refused}")
            return "refused", zero
        if not plan.anything:
            return "nothing_to_push", zero
        progress.stage("push")
        record = await execute_push(self.robot, plan, self.run_dir, self.robot_info.address,
                                    journal=self.journal)
        labels = plan.display_names()
        progress.message("pushed zero offsets: " + ", ".join(
            f"{labels[j]} {math.degrees(o):+.4f}->{math.degrees(n):+.4f}"
            for j, (o, n) in enumerate(zip(plan.old, plan.new, strict=True)) if plan.pushed[j])
            + f" deg (rollback id {record.rollback_id})")
        return "pushed", plan.delta.copy()

    def _push_asked(self) -> bool:
        """True if this resume's command line asked for the push (--push or --force)."""
        return (self.resume_overrides.get("push") is True
                or self.resume_overrides.get("force") is True)

    def _export_offsets(self, robot_name: str, plan: PushPlan, status: str
                        ) -> dict[str, str] | None:
        """For a robot that keeps no zero offsets (an adapter with `export_offsets`, the UR
        driver) write the compensated offsets as files into the run folder: the only lasting
        form of its push. None if the adapter writes the controller or nothing is pushed."""
        export = getattr(self.robot, "export_offsets", None)
        if (not callable(export) or status not in ("pushed", "disabled") or plan.refused
                or not plan.anything):
            return None
        paths = export(self.run_dir, robot_name, plan.new)
        self.progress.message("offsets exported for the robot's own software: "
                              + ", ".join(str(path) for path in paths.values()))
        return {kind: str(path) for kind, path in paths.items()}

    def _write_report(self, dataset: Dataset, settings: RunSettings,
                      document: dict[str, Any], truth: dict[str, Any] | None) -> str | None:
        """report.html (the result, then the diagnosis) through hostpc.report."""
        try:
            from hostpc.diagnostics import diagnose
            from hostpc.report import write_calibration_report
        except ImportError:
            return None
        self.progress.stage("report")
        path = self.run_dir / "report.html"
        try:
            diagnosis = diagnose(dataset, settings.effects, plugins=settings.plugins,
                                 source=str(self.run_dir / "dataset.json"))
            write_calibration_report(path, document, diagnosis, truth)
        except Exception as exc:  # the report is an extra: never lose a run over it
            self.progress.message(f"report not written: {type(exc).__name__}: {exc}")
            return None
        return str(path)


def _state_dict(state: RobotState, offsets: np.ndarray) -> dict[str, Any]:
    return {
        "robot": state.robot,
        "q": [float(v) for v in state.q],
        "zero_offsets": [float(v) for v in offsets],
        "q_min": [float(v) for v in state.q_min],
        "q_max": [float(v) for v in state.q_max],
        "time": finite_or_none(float(state.extra.get("time", 0.0) or 0.0)),
        "camera": state.camera,
    }
