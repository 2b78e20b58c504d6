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
    --  result.json, summary.txt and, if the diagnostics/report packages exist, report.html

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
from hostpc.methods.base import Method, NullProgress, Plan, Progress, RunSettings, SampleRecord
from hostpc.methods.cell import Cell, build_cell, cell_from_dict
from hostpc.methods.journal import Journal, sample_times, shift_sample_t, write_json_atomic
from hostpc.methods.planning import (
    check_plan,
    design_matrix,
    joint_offset_sigmas,
    make_design,
    order_for_travel,
    select,
    select_groups,
    verify_groups,
)
from hostpc.methods.push import (
    PUSH_FILE,
    PushPlan,
    PushRecord,
    chi2_dof_upper,
    execute_push,
    intent_outcome,
    joint_display_name,
    plan_push,
    same_offsets,
)
from hostpc.methods.verify import VerifyResult, evaluate_verify, measured_noise_rms, noise_rms
from hostpc.robots.base import RobotAdapter, RobotState

RESULT_FORMAT = "zerocal-calibration/1"
RESUME_OVERRIDABLE = frozenset({"push", "force", "max_correction_deg", "verify_factor"})
"""Settings a resume may change (they act after the measurements)."""
EXIT_PUSH_REFUSED = 5
EXIT_VERIFY_FAILED = 6
CLOCK_TOLERANCE_S = 1e-6


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
        self._last_t: float | None = None  # resume: the last journaled sample's t (s)
        self._t_shift: float | None = None  # resume: added to new samples' t (s)

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
            settings = RunSettings.from_dict(self.header["settings"])
            overrides = {k: v for k, v in self.resume_overrides.items()
                         if k in RESUME_OVERRIDABLE and v is not None
                         and getattr(settings, k) != v}
            if overrides:
                settings = dataclasses.replace(settings, **overrides)
                self.journal.event("note", text="settings changed on resume",
                                   overrides=overrides)
                progress.message("resume with " + ", ".join(
                    f"{k}={v}" for k, v in overrides.items()))
            cell = cell_from_dict(self.header["cell"])
            initial = self.header["initial"]
            self._check_resume_offsets(np.asarray(initial["zero_offsets"], float), offsets)
            self._last_t = self.journal.last_sample_t()
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
            method.set_time_origin(self._time_origin(initial, state))
        if settings.effects is None and method.default_effects() is not None:
            # the method's own default model (sphere_probe: + trigger_latency)
            settings = dataclasses.replace(settings, effects=method.default_effects())
        method.check_inputs()
        await method.prepare(self.robot, progress)

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
        q_now = await self._acquire(method, "fit", plan.q, q_now)

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
            await self._acquire(method, "verify", plan.q_verify, q_now)
            verify_dataset = self._dataset(method, "verify")
            if verify_dataset.n_samples > 0:
                save_dataset(verify_dataset, self.run_dir / "verify_dataset.json")
                verify_result = evaluate_verify(result, verify_dataset, pushed_delta,
                                                plan.q_verify.shape[0],
                                                settings.verify_factor)
                write_json_atomic(self.run_dir / "verify.json", verify_result.to_dict())

        document = self._document(settings, cell, plan, method, dataset, result, push_plan,
                                  push_status, verify_result, truth)
        if exports is not None:  # the robot keeps no offsets (UR): these files are the push
            document["push"].update(on_controller=False, exports=exports)
            document["files"].update({f"ur_{kind}": path for kind, path in exports.items()})
        summary = format_summary(document)
        (self.run_dir / "summary.txt").write_text(summary + "\n", encoding="utf-8")
        if self.report:
            report_file = self._write_report(dataset, settings)
            if report_file:
                document["files"]["report"] = report_file
        write_json_atomic(self.run_dir / "result.json", document)
        progress.close()
        return RunOutcome(self.run_dir, document, summary, document["exit_code"], result,
                          dataset, verify_result, push_plan)

    # ------------------------------------------------------------------ steps

    def _check_resume_offsets(self, initial: np.ndarray, now: np.ndarray) -> None:
        """A resume continues only if the controller's offsets are the run's initial ones,
        the ones it pushed, or the ones a push cut short meant to write."""
        pushes = self.journal.events("push")
        if same_offsets(now, initial):
            return
        if pushes and same_offsets(now, pushes[-1]["new_offsets"]):
            return
        last = self.journal.last_event("push_intent", "push")
        if last is not None and last["event"] == "push_intent" and same_offsets(
                now, last["new_offsets"]):
            return
        raise InputError(
            f"the controller's zero offsets changed since the run in {self.run_dir} started "
            f"(now {_deg_list(now)} deg, then {_deg_list(initial)} deg); the journaled "
            "samples cannot be combined with new ones: start a new run")

    def _time_origin(self, initial: Mapping[str, Any], state: RobotState) -> float:
        """The controller time (s) sample `t` counts from: the run's start; on a resume
        whose controller clock went back (a restarted controller, e.g. a resumed `--robot
        sim` run) moved so that the new samples' t continue from the last journaled one."""
        t0 = float(initial.get("time") or 0.0)
        now = state.extra.get("time")
        if self._last_t is None or not isinstance(now, int | float) or not math.isfinite(now):
            return t0
        if float(now) < t0 + self._last_t - CLOCK_TOLERANCE_S:
            origin = float(now) - self._last_t
            self.journal.event("note", text="controller clock restarted: new samples' t "
                               "continue from the last journaled one", last_t=self._last_t,
                               time_origin=origin)
            self.progress.message(f"the controller's clock restarted: sample t continues "
                                  f"from {self._last_t:.1f} s")
            return origin
        return t0

    def _continue_t(self, record: SampleRecord) -> SampleRecord:
        """On a resume, keep `t` from going backwards for any method (e.g. one that times
        samples with the host's clock): the first new sample sets the shift."""
        times = sample_times(record.sample)
        if self._last_t is None or not times or record.sample is None:
            return record
        if self._t_shift is None:
            self._t_shift = max(0.0, self._last_t - min(times))
            if self._t_shift > 0.0:
                self.journal.event("note", text="sample t went backwards on resume; new "
                                   "samples' t shifted", t_shift=self._t_shift)
        if self._t_shift == 0.0:
            return record
        return dataclasses.replace(record, sample=shift_sample_t(record.sample,
                                                                  self._t_shift))

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
            fit_indices = chosen[order_for_travel(pool[chosen], state.q)]
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
            record = self._continue_t(record)
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
        self._settle_push_intent(offsets_now)
        zero = np.zeros_like(plan.old)
        pushes = self.journal.events("push")
        if pushes:
            new = np.asarray(pushes[-1]["new_offsets"], float)
            previous = np.asarray(pushes[-1]["previous_offsets"], float)
            if same_offsets(offsets_now, new):
                return "pushed", new - previous
            if same_offsets(offsets_now, previous) and not self._push_asked():
                progress.message(
                    f"the push journaled in {self.run_dir} was rolled back (the controller "
                    "has its previous offsets again): not pushing again; resume with --push "
                    "(or --force) to push again")
                return "rolled_back", zero
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

    def _settle_push_intent(self, offsets_now: np.ndarray) -> None:
        """A `push_intent` without its result (the run stopped while writing the offsets):
        the controller's offsets say whether the write happened. Written: journal it as the
        push (no rollback id; `hostpc rollback --run` writes the previous offsets). Not
        written: note it and drop the intent's push.json."""
        last = self.journal.last_event("push_intent", "push")
        if last is None or last["event"] != "push_intent":
            return
        outcome = intent_outcome(last, offsets_now)
        if outcome == "pushed":
            record = PushRecord(previous=np.asarray(last["previous_offsets"], float),
                                new=np.asarray(last["new_offsets"], float), rollback_id=None,
                                pushed=tuple(bool(v) for v in last.get("pushed", ())),
                                time=str(last.get("time", "")))
            self.journal.event("push", **record.to_dict(), recovered=True)
            write_json_atomic(self.run_dir / PUSH_FILE,
                              {"controller": self.robot_info.address, "status": "pushed",
                               **record.to_dict(), "recovered": True})
            self.progress.message("the push cut short in the last session reached the "
                                  "controller (it has the intended offsets): recorded as "
                                  "pushed, without a rollback id")
        elif outcome == "not_pushed":
            self.journal.event("note", text="the push cut short in the last session did not "
                               "reach the controller")
            (self.run_dir / PUSH_FILE).unlink(missing_ok=True)
            self.progress.message("the push cut short in the last session did not reach the "
                                  "controller (it has the previous offsets)")

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

    def _write_report(self, dataset: Dataset, settings: RunSettings) -> str | None:
        """report.html through hostpc.diagnose + hostpc.report, if both are installed."""
        try:
            from hostpc.diagnostics import diagnose
            from hostpc.report import write_report  # type: ignore[attr-defined]
        except ImportError:
            return None
        self.progress.stage("report")
        path = self.run_dir / "report.html"
        try:
            diagnosis = diagnose(dataset, settings.effects, plugins=settings.plugins,
                                 source=str(self.run_dir / "dataset.json"))
            write_report(path, diagnosis)
        except Exception as exc:  # the report is an extra: never lose a run over it
            self.progress.message(f"report not written: {type(exc).__name__}: {exc}")
            return None
        return str(path)

    # ------------------------------------------------------------------ result

    def _document(self, settings: RunSettings, cell: Cell, plan: Plan, method: Method,
                  dataset: Dataset, result: FitResult, push_plan: PushPlan, push_status: str,
                  verify_result: VerifyResult | None, truth: dict[str, Any] | None
                  ) -> dict[str, Any]:
        skipped = [{"phase": r.phase, "index": r.index, "reason": r.reason}
                   for phase in ("fit", "verify") for r in self.journal.records(phase)
                   if not r.ok]
        joints = push_plan.joints()
        written = push_status == "pushed"
        for row in joints:
            row["pushed"] = bool(row["pushed"] and written)
            if not written:
                row["new_deg"] = row["old_deg"]
        push_doc: dict[str, Any] = {"status": push_status, "reason": push_plan.refused,
                                    "max_correction_deg": push_plan.max_correction_deg}
        pushes = self.journal.events("push")
        if written and pushes:
            push_doc["rollback_id"] = pushes[-1]["rollback_id"]
            push_doc["recovered"] = bool(pushes[-1].get("recovered", False))
            push_doc["file"] = str(self.run_dir / PUSH_FILE)
        # with nothing pushed the verification is a model check: reported, never exit 6
        if push_status == "refused":
            exit_code = EXIT_PUSH_REFUSED
        elif (verify_result is not None and verify_result.pushed
              and not verify_result.passed):
            exit_code = EXIT_VERIFY_FAILED
        else:
            exit_code = 0
        document: dict[str, Any] = {
            "format": RESULT_FORMAT,
            "run_dir": str(self.run_dir),
            "robot": {**self.robot_info.to_dict(), "name": cell.robot},
            "method": settings.method,
            "settings": settings.to_dict(),
            "known": list(cell.known),
            "method_setup": method.describe(),
            "plan": {
                "n_poses": int(plan.q.shape[0]),
                "n_verify": int(plan.q_verify.shape[0]),
                **{k: v for k, v in plan.info.items() if k != "parameters"},
            },
            "acquisition": {
                "n_planned": int(plan.q.shape[0]),
                "n_measured": dataset.n_samples,
                "n_poses_measured": sum(r.ok for r in self.journal.records("fit")),
                "n_skipped": len(skipped),
                "skipped": skipped,
            },
            "fit": {
                "converged": result.converged,
                "effects": list(result.problem.effect_names),
                "rms_mm": result.rms * 1e3,
                "max_mm": result.max * 1e3,
                "chi2_dof": _finite(result.chi2_dof),
                "chi2_dof_upper": _finite(chi2_dof_upper(result.dof)),
                "noise_rms_mm": _finite(measured_noise_rms(result) * 1e3),
                "stated_noise_rms_mm": _finite(noise_rms(dataset) * 1e3),
                "cv_rms_mm": None if result.cv_rms is None else result.cv_rms * 1e3,
                "rank": result.rank,
                "n_parameters": len(result.names),
                "unidentifiable": [d.description for d in result.unidentifiable],
                "file": str(self.run_dir / "fit.json"),
            },
            "offsets": {"joints": joints},
            "push": push_doc,
            "verify": verify_result.to_dict() if verify_result is not None else None,
            "files": {
                "run": str(self.journal.run_path),
                "journal": str(self.journal.journal_path),
                "dataset": str(self.run_dir / "dataset.json"),
                "fit": str(self.run_dir / "fit.json"),
                "summary": str(self.run_dir / "summary.txt"),
                "result": str(self.run_dir / "result.json"),
            },
            "exit_code": exit_code,
        }
        if truth is not None:
            document["truth"] = truth_comparison(truth, push_plan)
        return document


def truth_comparison(truth: Mapping[str, Any], push_plan: PushPlan) -> dict[str, Any]:
    """Fitted vs injected zero errors (simulation): `joint_offsets_error_deg` = fitted -
    true per joint, None where the joint is unidentifiable; also within 3 sigma."""
    true = np.asarray(truth.get("zero_errors", []), float)
    errors: list[float | None] = []
    within: list[bool | None] = []
    for j in range(true.size):
        if j < push_plan.sigma.size and np.isfinite(push_plan.sigma[j]):
            e = float(push_plan.fitted[j] - true[j])
            errors.append(math.degrees(e))
            within.append(bool(abs(e) <= 3.0 * float(push_plan.sigma[j])))
        else:
            errors.append(None)
            within.append(None)
    finite = [abs(e) for e in errors if e is not None]
    return {
        "zero_errors_deg": [math.degrees(v) for v in true],
        "joint_offsets_error_deg": errors,
        "within_3_sigma": within,
        "max_abs_error_deg": max(finite) if finite else None,
    }


def _state_dict(state: RobotState, offsets: np.ndarray) -> dict[str, Any]:
    return {
        "robot": state.robot,
        "q": [float(v) for v in state.q],
        "zero_offsets": [float(v) for v in offsets],
        "q_min": [float(v) for v in state.q_min],
        "q_max": [float(v) for v in state.q_max],
        "time": _finite(float(state.extra.get("time", 0.0) or 0.0)),
        "camera": state.camera,
    }


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _deg_list(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{math.degrees(v):+.4f}" for v in values) + "]"


def format_summary(document: Mapping[str, Any]) -> str:
    """The human-readable summary of a result document (mm and degrees)."""
    robot = document["robot"]
    plan, acq, fitd = document["plan"], document["acquisition"], document["fit"]
    lines = [
        f"zerocal calibration: {document['method']} on {robot['name']} at "
        f"{'sim (' + robot['address'] + ')' if robot.get('sim') else robot['address']}",
        f"run folder: {document['run_dir']}",
        f"known frames: {', '.join(document['known']) or 'none (every frame estimated)'}",
        f"plan: {plan['n_poses']} poses ({plan.get('criterion', '?')}-optimal from "
        f"{plan.get('n_candidates', '?')} candidates), {plan['n_verify']} verification poses",
        f"measured: {acq.get('n_poses_measured', acq['n_measured'])} of {acq['n_planned']} "
        "fit poses"
        + (f" ({acq['n_measured']} samples)"
           if acq.get("n_poses_measured", acq["n_measured"]) != acq["n_measured"] else "")
        + (f", {acq['n_skipped']} skipped" if acq["n_skipped"] else ""),
        f"fit: {'converged' if fitd['converged'] else 'NOT CONVERGED'}, effects "
        f"{', '.join(fitd['effects'])}; residual RMS {fitd['rms_mm']:.4f} mm "
        f"(max {fitd['max_mm']:.4f}), measured noise RMS {_mm(fitd['noise_rms_mm'])} mm "
        f"(stated {_mm(fitd.get('stated_noise_rms_mm'))}), chi2/dof "
        f"{fitd['chi2_dof'] if fitd['chi2_dof'] is None else round(fitd['chi2_dof'], 3)}",
    ]
    for text in fitd["unidentifiable"]:
        lines.append(f"  unidentifiable: {text}")
    for item in acq["skipped"][:10]:
        lines.append(f"  skipped {item['phase']} pose {item['index']}: {item['reason']}")
    rows = document["offsets"]["joints"]
    names = [joint_display_name(j, row.get("label", "")) for j, row in enumerate(rows)]
    width = max([6, *(len(name) + 2 for name in names)])
    lines += ["", f"  {'joint':<{width}}{'old [deg]':>12}{'correction':>13}{'+/- sigma':>11}"
                  f"{'new [deg]':>12}  pushed"]
    for name, row in zip(names, rows, strict=True):
        corr = "-" if row["correction_deg"] is None else f"{row['correction_deg']:+.5f}"
        sig = "-" if row["sigma_deg"] is None else f"{row['sigma_deg']:.5f}"
        pushed = "yes" if row["pushed"] else ("no: " + row["note"] if row["note"] else "no")
        lines.append(f"  {name:<{width}}{row['old_deg']:>12.5f}{corr:>13}"
                     f"{sig:>11}{row['new_deg']:>12.5f}  {pushed}")
    lines.append("")
    lines.append(_push_line(document))
    verify = document.get("verify")
    if verify:
        lines.append(_verify_line(verify))
    truth = document.get("truth")
    if truth:
        errors = ", ".join(
            f"{names[j] if j < len(names) else f'J{j + 1}'} "
            + ("-" if e is None else f"{e:+.5f}")
            for j, e in enumerate(truth["joint_offsets_error_deg"]))
        lines.append(f"truth (simulation): fitted - true [deg]: {errors}")
        inside = [w for w in truth["within_3_sigma"] if w is not None]
        if inside:
            lines.append(f"  {sum(inside)} of {len(inside)} identifiable offsets within 3 sigma"
                         f", largest error {truth['max_abs_error_deg']:.5f} deg")
    return "\n".join(lines)


def _mm(value: float | None) -> str:
    return "-" if value is None else f"{value:.4f}"


def _push_line(document: Mapping[str, Any]) -> str:
    """The summary's push line: what happened to the controller and how to undo it."""
    push = document["push"]
    status = push["status"]
    if status == "pushed" and push.get("on_controller") is False:
        return ("push: applied on the host for this session only (UR has no writable zero "
                f"offsets); load {push['exports']['yaml']} in your UR/ROS setup")
    if status == "pushed":
        if document["robot"].get("sim"):
            undo = "simulated controller: nothing to roll back after the run"
        else:
            undo = f"undo with hostpc rollback --run {document['run_dir']}"
        rollback_id = push.get("rollback_id")
        what = (f"rollback id {rollback_id}" if rollback_id is not None
                else "recovered after an interruption, no rollback id")
        return f"push: written ({what}; {undo})"
    if status == "refused":
        return f"push: REFUSED: {push['reason']}"
    if status == "disabled":
        return ("push: not requested (--no-push); the controller is unchanged"
                + (f"; offsets for your UR/ROS setup: {push['exports']['yaml']}"
                   if push.get("exports") else ""))
    if status == "rolled_back":
        return ("push: not repeated: this run's push was rolled back (the controller has its "
                "previous offsets); resume with --push or --force to push again")
    return "push: nothing to push (no identifiable joint offset)"


def _verify_line(verify: Mapping[str, Any]) -> str:
    """The summary's verification line. With nothing pushed it checks the model on fresh
    poses (no PASS: no offsets were verified)."""
    poses = (f"{verify['n_planned']} fresh poses ({verify['n_measured']} samples)"
             if verify["n_measured"] > verify["n_planned"]  # dual_loop: two targets a pose
             else f"{verify['n_measured']} fresh poses")
    noise = (f"noise RMS the fit measured {_mm(verify['noise_rms_mm'])} mm (stated "
             f"{_mm(verify.get('stated_noise_rms_mm'))})")
    bound = f"{verify['factor']:g} x noise = {_mm(verify['threshold_mm'])} mm"
    if not verify.get("pushed", True):
        return (f"model check on fresh poses (nothing pushed): {poses}: RMS with the fitted "
                f"model {verify['rms_after_mm']:.4f} mm (max {verify['max_after_mm']:.4f}), "
                f"with the controller's offsets as they are {verify['rms_before_mm']:.4f} mm "
                f"(max {verify['max_before_mm']:.4f}); {noise}; the model "
                + ("explains" if verify["passed"] else "does NOT explain")
                + f" them (RMS {'<=' if verify['passed'] else '>'} {bound})")
    return (f"verify: {poses}: RMS before (old offsets) {verify['rms_before_mm']:.4f} mm "
            f"(max {verify['max_before_mm']:.4f}), after {verify['rms_after_mm']:.4f} mm "
            f"(max {verify['max_after_mm']:.4f}); {noise}; pass if RMS after <= {bound}: "
            + ("PASS" if verify["passed"] else "FAIL"))
