"""The calibration procedure every method shares (`hostpc calibrate`).

    S1  read the controller's state and zero offsets; build the nominal cell
    --  method.prepare (e.g. the stereo rig), persisted in the run folder
    --  plan (run_plan.py): informative fit poses + verification poses, identifiability
        checked BEFORE moving; plan, seed and settings go into run.json
    S2  acquire: one journaled sample per pose (journal.py); an aborted move is measured
        again (refusals.py); a resume skips what is there
    S3  dataset.json from the measured fit poses; S4 fit (fit.json)
    S5  guarded push (push.py); verify (verify.py): a chi-square test on fresh poses
        measured under the pushed offsets; result.json, summary.txt (summary.py), report

A resume (resume.py) checks the controller's offsets, settles a push cut short, prints a
finished run's stored result unchanged, and tells a lost push from a rollback. Controller
refusals end as one `RunStopped` line with the resume hint (exit 4). The verdict and exit
code are the run's outcome (outcome.py, from the journal): 5 = push refused, 6 =
verification of the pushed offsets failed, 7 = a required joint not calibrated.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hostpc.calibrate import run_reference as cell_reference
from hostpc.calibrate.joint_status import joint_sources
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import (
    MorePoses,
    Pushed,
    PushIntent,
    Resumed,
    Rollback,
    RunFinished,
    Verified,
    VerifyRoundLost,
)
from hostpc.calibrate.measured_under import measured_under_field
from hostpc.calibrate.more_poses import more_poses_message, more_poses_reason
from hostpc.calibrate.next_commands import resume_command, rollback_command
from hostpc.calibrate.outcome import parse_required_joints, restored_to_reference
from hostpc.calibrate.outcome_files import run_outcome
from hostpc.calibrate.push import (
    PUSH_FILE,
    PushMismatch,
    PushPlan,
    execute_push,
    export_offsets,
    plan_push,
    read_back_lost_line,
    same_offsets,
    written_rollback_id,
)
from hostpc.calibrate.refusals import (
    MAX_POSE_ATTEMPTS,
    PushRefusal,
    RunStopped,
    refusal_text,
    stopped,
)
from hostpc.calibrate.resume import (
    PushLost,
    ResumeOverrides,
    SampleClock,
    VerifyLost,
    archive_result,
    check_resume_offsets,
    persisted,
    push_state,
    resume_pose,
    resume_settings,
    settle_push_intent,
    stored_result,
    verify_lost_line,
    verify_round,
)
from hostpc.calibrate.robot_time import RobotTimer
from hostpc.calibrate.run_header import InitialState, RunHeader, read_run_header
from hostpc.calibrate.run_plan import plan_run
from hostpc.calibrate.run_report import write_run_report
from hostpc.calibrate.run_values import RobotInfo, RunOutcome
from hostpc.calibrate.separate import (
    SEPARATION_FILE,
    plan_separation,
    retest,
    untestable,
)
from hostpc.calibrate.summary import (
    finite_or_none,
    format_summary,
    run_result,
)
from hostpc.calibrate.swaps import (
    Staging,
    controller_limit_refusal,
    joint_limits_deg,
    lost_plan_line,
    swap_message,
)
from hostpc.calibrate.verify import VerifyResult, evaluate_verify
from hostpc.dataset import Dataset, save_dataset
from hostpc.errors import ConnectionFailed, ControllerError, InputError, ZerocalError
from hostpc.files import write_json_atomic
from hostpc.fitting import FitResult, fit
from hostpc.fitting.priors import with_constraints
from hostpc.json_object import JsonObject
from hostpc.methods import method_class
from hostpc.methods.base import (
    Method,
    NullProgress,
    Plan,
    Progress,
    RunSettings,
)
from hostpc.methods.cell import build_cell, cell_from_dict
from hostpc.robots.base import RobotAdapter, RobotState, check_needs

__all__ = ["Runner"]

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
        cell_file: JsonObject | None = None,
        known: tuple[str, ...] | None = None,
        default_known: tuple[str, ...] = (),
        progress: Progress | None = None,
        truth: Callable[[], JsonObject] | None = None,
        report: bool = True,
        resume_overrides: ResumeOverrides | None = None,
        reference: str | None = None,
        robot_serial: str | None = None,
        archive: str | None = None,
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
        self.resume_overrides = resume_overrides or ResumeOverrides()
        self.reference_option = reference  # --reference FILE|none (run_reference.py)
        self.robot_serial = robot_serial
        self.archive = archive  # --db, without a password (RunHeader.archive)
        self.reference: Any = None  # the CellReference the run uses, and its frames' priors
        self._priors: list[Any] = []
        self.journal = Journal(self.run_dir)
        self._clock = SampleClock(self.journal, self.progress)  # resume: sample t continues
        self._controller_refusal: PushRefusal | None = None  # the controller's own limit
        self._read_pushed = False
        """q_now is under the pushed offsets already (resume_pose after a verification
        pose): the staging's `reading_after_push` must not add them again."""

    # ------------------------------------------------------------------ top level

    async def run(self) -> RunOutcome:
        """Run (or resume) the whole procedure; see the module docstring."""
        resume = self.journal.exists
        try:
            return await self._run(resume)
        except ConnectionFailed as exc:
            raise ConnectionFailed(
                f"{exc}; {self._journaled()} {self._go_on(link_lost=True)}") from exc
        except PushLost as exc:
            if not self.robot_info.sim:
                raise
            raise PushLost(f"{exc} (a resumed --robot sim run restarts the simulated "
                           "controller with its initial offsets)") from None
        except (VerifyLost, PushMismatch):
            raise  # its message says what happened and how to go on
        except ControllerError as exc:
            hint = (f"{self._journaled()} {self._go_on()}" if self.journal.exists
                    else "nothing measured yet; rerun when the controller is ready")
            raise RunStopped(f"{refusal_text(exc)}; {hint}", getattr(exc, "code", None),
                             getattr(exc, "reason", None)) from exc

    def _journaled(self) -> str:
        if not self.journal.exists:
            return "nothing measured yet;"
        n = len(self.journal.records("fit")) + len(self.journal.records("verify"))
        return f"{n} poses journaled in {self.run_dir};"

    def _go_on(self, link_lost: bool = False) -> str:
        """The next step after a run stopped early, with what the controller holds when the
        journal says this run wrote its offsets and no rollback undid them since;
        `link_lost`: the link closed, so what it held then may have changed since (a
        controller that restarted has its previous offsets again)."""
        resume = resume_command(self.run_dir, archive=self.archive)
        last = self.journal.last_event(PushIntent, Pushed, Rollback) if self.journal.exists \
            else None
        if isinstance(last, PushIntent):  # the controller's answer never came
            if self.robot_info.sim:  # its simulated controller ended with the run
                return ("a push was cut short: the simulated controller may have held the "
                        "new offsets, NOT verified, and ended with the run; a resume "
                        "restarts it with its initial offsets and pushes again: "
                        f"{resume_command(self.run_dir, '--push', archive=self.archive)}")
            written = written_rollback_id(self.journal)
            if written is not None:  # answered, but its read-back never came
                return (f"{read_back_lost_line(written, self.run_dir, self.robot_info.address)}"
                        f"; settle and verify it with: {resume}")
            return (f"a push was cut short: the controller may hold the new offsets, NOT "
                    f"verified; settle and verify it with: {resume} (undo: "
                    f"{rollback_command(self.run_dir, self.archive)})")
        if not isinstance(last, Pushed):
            return f"continue with: {resume}"
        record = last.record
        at = f"the offsets pushed at {record.time or 'an unrecorded time'}"
        rollback_id = f" (rollback id {record.rollback_id})" if record.rollback_id else ""
        pushed = at + rollback_id
        verified = self.journal.last(Verified)
        verdict = ("NOT verified" if verified is None or self.journal.last_position(Verified)
                   < self.journal.last_position(Pushed) else f"verification {verified.verdict}")
        if self.robot_info.sim:  # its simulated controller ends with this command
            return (f"the simulated controller held {pushed}, {verdict}, and ended with the "
                    f"run; a resume restarts it with its initial offsets: "
                    f"{resume_command(self.run_dir, '--push', archive=self.archive)}")
        undo = f"undo: {rollback_command(self.run_dir, self.archive)}"
        if link_lost:
            return (f"the controller held {at} when the link was lost{rollback_id}, "
                    f"{verdict}; the resume checks what it holds now: {resume}; {undo}")
        return f"the controller holds {pushed}, {verdict}; verify: {resume}; {undo}"

    async def _run(self, resume: bool) -> RunOutcome:
        progress = self.progress
        progress.stage("read controller")
        state = await self.robot.state()
        offsets = np.asarray(await self.robot.get_offsets(), float)
        truth = self.truth_reader() if self.truth_reader is not None else None

        if resume:
            header = read_run_header(self.journal)
            self.journal.load()
            initial = header.initial
            check_resume_offsets(self.journal, self.run_dir, initial.offsets, offsets,
                                 self.robot_info.address)
            settle_push_intent(self.journal, self.run_dir, self.robot_info.address, progress,
                               offsets)
            if self.resume_overrides.separate and self._pushed_ever():
                raise InputError(
                    "--separate: this run pushed offsets, and poses measured under them "
                    "cannot join its data; separate on a run that pushed nothing (e.g. "
                    f"hostpc calibrate ... --no-push), or roll back (hostpc rollback --run "
                    f"{self.run_dir}) and start a new run")
            stored = stored_result(self.journal, self.run_dir, offsets, self._asked(),
                                   progress)
            if stored is not None:
                progress.close()
                return RunOutcome(self.run_dir, stored, format_summary(stored),
                                  stored.exit_code)
            settings = resume_settings(header.settings, self.resume_overrides, self.journal,
                                       progress)
            if settings is not header.settings:  # kept for the next resume (resume.py)
                header = dataclasses.replace(header, settings=persisted(
                    settings, header.settings, self.resume_overrides))
                self.journal.write_header(header.to_dict())
            if self.archive is None:  # the run's own archive (next_commands.py)
                self.archive = header.archive
            elif self.archive != header.archive:
                header = dataclasses.replace(header, archive=self.archive)
                self.journal.write_header(header.to_dict())
            self.journal.append(Resumed(at=_now()))
            cell, header = cell_reference.resume_known(
                cell_from_dict(header.cell, settings.plugins), self.known, header,
                self.journal, progress)
            self._clock.last_t = self.journal.last_sample_t()
            progress.message(f"resuming {self.run_dir}: "
                             f"{len(self.journal.records('fit'))} fit and "
                             f"{len(self.journal.records('verify'))} verify poses journaled")
        else:
            if self.settings is None:
                raise InputError("a new run needs settings")
            settings = self.settings
            try:  # a joint the robot does not have: one line before anything moves
                parse_required_joints(settings.require_joints, len(offsets))
            except ValueError as exc:
                raise InputError(str(exc)) from None
            beyond = [j for j in settings.swapped if not 1 <= j <= len(offsets)]
            if beyond:
                raise InputError(f"--swapped J{beyond[0]}: the robot has {len(offsets)} joints "
                                 f"(J1..J{len(offsets)})")
            cell = build_cell(state.camera, state.robot, self.cell_file, self.known,
                              self.default_known, settings.plugins)
            initial = _initial_state(state, offsets)
            header = RunHeader(_dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
                               self.robot_info, self.robot_serial, settings, cell.to_dict(),
                               initial, archive=self.archive)

        method = method_class(settings.method, settings.plugins)(settings, cell, self.run_dir)
        clock = method.sample_clock()
        if clock is not None:
            clock.set_time_origin(self._clock.time_origin(initial.time, state))
        if settings.effects is None and method.default_effects() is not None:
            # the method's own default model (sphere_probe: + trigger_latency)
            settings = dataclasses.replace(settings, effects=method.default_effects())
        method.check_inputs()
        self.reference, changed = cell_reference.choose_reference(
            self.run_dir, self.reference_option, resume=resume, method=settings.method,
            robot_model=cell.robot, robot_serial=self.robot_serial)
        if not resume:  # the run exists from here on (a failed check leaves nothing)
            self.journal.write_header(header.to_dict())
        cell_reference.record_reference_choice(self.run_dir, self.journal, self.reference,
                                               changed, self.reference_option, progress)
        self._timer = RobotTimer(self.robot, self.journal, state)  # robot time (robot_time.py)
        check_needs(self.robot, method.needs, f"--method {settings.method}")
        await method.prepare(self.robot, progress)
        await self._timer.end("rig")

        if header.plan is not None:
            plan = header.plan
        else:
            plan = plan_run(method, state, settings, progress, self.reference)
            header = dataclasses.replace(header, plan=plan)
            self.journal.write_header(header.to_dict())
        plan = cell_reference.with_joint_coverage(plan, method, settings, cell, self.reference,
                                                  progress)
        for text in plan.info.get("structural_unidentifiable", []):
            progress.message(f"note: {text}")
        limits_deg = joint_limits_deg(len(offsets), settings)
        if (text := swap_message(settings)) is not None:
            progress.message(text)

        q_now = (resume_pose(self.journal, state.q, offsets, initial.offsets, progress)
                 if resume else np.asarray(state.q, float))
        last_end = self.journal.last_end() if resume else None
        self._read_pushed = last_end is not None and last_end[0] == "verify"
        self._timer.begin()
        q_now = await self._acquire(method, "fit", plan.q, q_now)
        await self._timer.end("measure")
        self._staging = Staging(method, self.journal, progress, state.q_min, state.q_max)
        if method.staged:  # a joint far off: measured again, shifted (swaps.py)
            q_now = await self._staging.run(
                plan.q, q_now, lambda q, now, first: self._measure(method, q, now, first),
                lambda first: self._fit(method, settings, first),
                lambda fitted: plan_push(fitted, offsets, force=True).fitted, settings,
                lambda q, now: self._try_pose(method, q, now))

        n_measured = sum(r.ok for r in self.journal.records("fit"))
        if n_measured < 3 and any(stopped(r) for r in self.journal.records("fit")):
            raise RunStopped(f"measurement stopped: only {n_measured} of {plan.q.shape[0]} fit "
                             "poses measured, their moves were stopped (aborted) again and "
                             "again")
        if n_measured < 3:
            raise ZerocalError(lost_plan_line(
                n_measured, plan.q.shape[0], [r.reason for r in self.journal.records("fit")
                                              if not r.ok], settings, self.run_dir,
                staged=method.staged))
        last = self._staging.last_fit  # the staging's fit of these poses, if it made one
        result, dataset = (last[1] if last is not None and last[0] == self._staging.first
                           else self._fit(method, settings, self._staging.first))
        reason = more_poses_reason(self.journal, plan, result, pushed=self._pushed_ever())
        if reason is not None:  # diagnostics need more data to see the missing effect
            progress.message(more_poses_message(reason, self.journal, plan))
            q_now = await self._measure(method, self._staging.shifted(plan.more), q_now,
                                        self._staging.first + plan.q.shape[0])
            result, dataset = self._fit(method, settings, self._staging.first)
        separate = self.resume_overrides.separate
        if separate:  # --separate A,B: the poses that tell them apart (separate.py)
            q_now, result, dataset = await self._separate(method, state, plan, settings,
                                                          result, dataset, separate, q_now)
        write_json_atomic(self.run_dir / "fit.json",  # with the offsets measured under
                          {**result.to_dict(), **measured_under_field(
                              self.run_dir / "dataset.json")})
        status = "converged" if result.converged else "NOT converged"
        progress.message(f"fit: RMS {result.rms * 1e3:.4f} mm, chi2/dof "
                         f"{result.chi2_dof:.3f}, {status}")
        check = cell_reference.check_run_reference(result, self._priors, settings, progress)

        initial_offsets = initial.offsets
        push_plan = plan_push(result, initial_offsets, settings.max_correction_deg,
                              settings.force, dataset_file=str(self.run_dir / "dataset.json"),
                              limits_deg=limits_deg)
        push_plan = cell_reference.refuse_if_moved(push_plan, check, self.reference,
                                                   self.run_dir)
        hint = method.refusal_hint() if push_plan.refusal is not None else None
        if hint and push_plan.refusal is not None:  # the method's suspect before --force
            reason = f"{hint}; {push_plan.refusal.reason}"
            push_plan = dataclasses.replace(
                push_plan, refused=reason,
                refusal=dataclasses.replace(push_plan.refusal, reason=reason))
        push_status, pushed_delta, offsets = await self._push(push_plan, settings, offsets)
        if self._controller_refusal is not None:
            push_plan = dataclasses.replace(push_plan, refused=self._controller_refusal.reason,
                                            refusal=self._controller_refusal)
        exports = export_offsets(self.robot, self.run_dir, cell.robot, push_plan,
                                 push_status, progress)

        verify_result: VerifyResult | None = None
        if (settings.n_verify > 0 and self._verify_poses(plan).shape[0] > 0
                and push_status != "rolled_back"):
            verify_result = await self._verify(method, plan, result, settings, offsets,
                                               pushed_delta, q_now)

        sources = restored_to_reference(joint_sources(result, initial_offsets.size),
                                        plan.info.get("joints"), self.reference)
        outcome = run_outcome(self.journal, sources,
                              run_dir=self.run_dir, header=header,
                              require_joints=settings.require_joints, finished=True,
                              known=cell.known, swapped=settings.swapped)
        run = run_result(self.journal, self.run_dir, self.robot_info, settings, cell,
                         plan, method, dataset, result, push_plan, push_status, verify_result,
                         truth, outcome=outcome.to_dict(), exports=exports,
                         reference_check=cell_reference.reference_check_block(
                             check, self.reference, self.run_dir))
        archive_result(self.run_dir)
        if self.report:
            report_file = write_run_report(self.run_dir, dataset, settings, run, truth,
                                           self.progress)
            if report_file:
                run = run.with_files(report=report_file)
        summary = format_summary(run)  # after the report: it names the report's path
        (self.run_dir / "summary.txt").write_text(summary + "\n", encoding="utf-8")
        write_json_atomic(self.run_dir / "result.json", run.to_dict())
        self.journal.append(RunFinished(
            exit_code=run.exit_code, push=push_status,
            verdict=None if verify_result is None else verify_result.verdict,
            outcome=outcome.verdict, at=_now(), offsets=tuple(float(v) for v in offsets)))
        progress.close()
        return RunOutcome(self.run_dir, run, summary, run.exit_code, result, dataset,
                          verify_result, push_plan)

    # ------------------------------------------------------------------ steps

    async def _acquire(self, method: Method, phase: str, q_plan: np.ndarray,
                       q_now: np.ndarray, first: int = 0) -> np.ndarray:
        """Measure every planned pose of `phase` not yet journaled (sample indices first ..
        first + K - 1, pose index - first); returns where the robot is. A pose whose move
        was stopped (an abort) is measured again, up to MAX_POSE_ATTEMPTS times."""
        progress = self.progress
        total = q_plan.shape[0]
        progress.stage("measure" if phase == "fit" else "verify", total)
        done = sum(first <= r.index < first + total for r in self.journal.records(phase))
        progress.advance(done)
        for pose in range(total):
            index = first + pose
            journaled = self.journal.get(phase, index)
            if (journaled is not None and (journaled.ok or not stopped(journaled))
                    or (phase == "fit" and self._pushed_ever())):
                continue  # measured, or skipped for good (fit poses: never after a push)
            for attempt in range(1, MAX_POSE_ATTEMPTS + 1):
                record = await method.acquire(self.robot, phase, index, q_plan[pose], q_now)  # type: ignore[arg-type]
                if record.q_end is not None:
                    q_now = np.asarray(record.q_end, float)
                if record.ok or not stopped(record) or attempt == MAX_POSE_ATTEMPTS:
                    break
                progress.message(f"{phase} pose {pose}: {record.reason}; measuring it again "
                                 f"(attempt {attempt + 1} of {MAX_POSE_ATTEMPTS})")
            if not record.ok and stopped(record) and MAX_POSE_ATTEMPTS > 1:
                record = dataclasses.replace(
                    record, reason=f"{record.reason} ({MAX_POSE_ATTEMPTS} attempts)")
            record = self._clock.continue_t(record)
            self.journal.record(record)
            # the pose's robot time, journaled with it: a session killed mid-phase keeps
            # the time of every pose it journaled (robot_time.py)
            await self._timer.end("measure" if phase == "fit" else "verify")
            done += 1
            if not record.ok:
                progress.message(f"{phase} pose {pose}: skipped ({record.reason})")
            progress.advance(done, f"{phase} pose {pose + 1}/{total}")
        return q_now

    async def _measure(self, method: Method, q_plan: np.ndarray, q_now: np.ndarray,
                       first: int) -> np.ndarray:
        """`_acquire` further fit poses from index `first`, timed as measurement."""
        self._timer.begin()
        q_now = await self._acquire(method, "fit", q_plan, q_now, first)
        await self._timer.end("measure")
        return q_now

    async def _separate(self, method: Method, state: RobotState, plan: Plan,
                        settings: RunSettings, result: FitResult, dataset: Dataset,
                        effects: tuple[str, str], q_now: np.ndarray
                        ) -> tuple[np.ndarray, FitResult, Dataset]:
        """Plan (or read back), measure and fit the separating poses of ``effects``, then
        test the pair again (separate.py)."""
        self.progress.stage("plan")
        planned = plan_separation(self.journal, method, state, plan, settings, result,
                                  effects)
        for line in planned.lines():
            self.progress.message(line)
        if planned.q.shape[0]:
            q_now = await self._measure(method, self._staging.shifted(planned.q), q_now,
                                        planned.first)
            result, dataset = self._fit(method, settings, self._staging.first)
        why_not = untestable(self.journal, planned, int(result.dof))
        if why_not is not None:
            write_json_atomic(self.run_dir / SEPARATION_FILE,
                              {"effects": list(effects), "tested": False, "sentence": why_not})
            self.journal.event("separated", effects=list(effects), tested=False)
            self.progress.message(f"separation: {why_not}")
            return q_now, result, dataset
        test = retest(self.journal, self.run_dir, result, settings, effects)
        self.progress.message(f"separation: {test.sentence}")
        return q_now, result, dataset

    async def _try_pose(self, method: Method, q: np.ndarray, q_now: np.ndarray
                        ) -> tuple[bool, np.ndarray]:
        """Measure one pose without journaling it (the coarse search, swaps.py)."""
        self._timer.begin()
        record = await method.acquire(self.robot, "fit", -1, q, q_now)
        await self._timer.end("measure")
        return record.ok, (q_now if record.q_end is None else np.asarray(record.q_end, float))

    def _fit(self, method: Method, settings: RunSettings, first: int = 0
             ) -> tuple[FitResult, Dataset]:
        """Fit every measured fit pose from index `first` on (a stage's, swaps.py;
        dataset.json written first, with the run's --prior / --hold and the cell
        reference's priors inside)."""
        dataset = with_constraints(self._dataset(method, "fit", first), settings.priors,
                                   settings.hold)
        dataset, self._priors = cell_reference.reference_priors(self.reference, dataset,
                                                                settings)
        save_dataset(dataset, self.run_dir / "dataset.json", plugins=settings.plugins)
        self.progress.stage("fit")
        return fit(dataset, settings.effects, plugins=settings.plugins, loss=settings.loss,
                   cv_folds=settings.cv_folds,
                   x0=self._staging.start_vector(dataset, settings)), dataset

    def _dataset(self, method: Method, phase: str, first: int = 0,
                 stop: int | None = None) -> Dataset:
        samples = [r.sample for r in self.journal.records(phase) if r.ok and r.sample
                   and first <= r.index and (stop is None or r.index < stop)]
        return method.dataset(samples)

    async def _verify(self, method: Method, plan: Plan, result: FitResult,
                      settings: RunSettings, offsets: np.ndarray, pushed_delta: np.ndarray,
                      q_now: np.ndarray) -> VerifyResult:
        """Measure this round's verification poses (all measured under `offsets`, the
        controller's now) and test them; VerifyLost if every pose was skipped."""
        q_verify = self._staging.shifted(self._verify_poses(plan), pushed_delta)
        if not self._read_pushed:  # a resume after a verification pose: read so already
            q_now = self._staging.reading_after_push(q_now, pushed_delta)
        n_verify = q_verify.shape[0]
        number, first = verify_round(self.journal, offsets, pushed_delta, n_verify)
        self._timer.begin()
        await self._acquire(method, "verify", q_verify, q_now, first)
        await self._timer.end("verify")
        if not any(r.ok for r in self.journal.records("verify")
                   if first <= r.index < first + n_verify):
            lost = [r for r in self.journal.records("verify")
                    if first <= r.index < first + n_verify]
            self.journal.append(VerifyRoundLost(round=number))
            raise VerifyLost(verify_lost_line(lost, n_verify, bool(np.any(pushed_delta != 0.0)),
                                              self.run_dir))
        verify_dataset = self._dataset(method, "verify", first, first + n_verify)
        save_dataset(verify_dataset, self.run_dir / "verify_dataset.json",
                     plugins=method.settings.plugins)
        tolerance = (None if settings.verify_tolerance_mm is None
                     else settings.verify_tolerance_mm * 1e-3)
        verify_result = evaluate_verify(result, verify_dataset, pushed_delta, n_verify,
                                        alpha=settings.verify_alpha, tolerance=tolerance,
                                        factor=settings.verify_factor)
        write_json_atomic(self.run_dir / "verify.json", verify_result.to_dict())
        self.journal.append(Verified(round=number, verdict=verify_result.verdict, at=_now(),
                                     statistic=finite_or_none(verify_result.statistic),
                                     dof=verify_result.dof,
                                     p_value=finite_or_none(verify_result.p_value),
                                     offsets=tuple(float(v) for v in offsets)))
        return verify_result

    async def _push(self, plan: PushPlan, settings: RunSettings, offsets_now: np.ndarray
                    ) -> tuple[str, np.ndarray, np.ndarray]:
        """Push (or not); returns (status, the delta now inside the controller relative to
        the run's initial offsets, the controller's offsets now).

        On a resume (resume.push_state): a journaled push whose offsets the controller has
        is "pushed" (pushed again only if the resume changed the model and the new fit's
        offsets differ); one it no longer has is "rolled_back" if `hostpc rollback`
        journaled it, else PushLost; --push / --force push again."""
        progress = self.progress
        zero = np.zeros_like(plan.old)
        journaled = push_state(self.journal, self.run_dir, progress, offsets_now,
                               self._push_asked(), zero)
        remodel = self.resume_overrides.remodel
        if journaled is not None and not (
                remodel and journaled[0] == "pushed" and not plan.refused and plan.anything
                and not same_offsets(plan.new, offsets_now)):
            return journaled[0], offsets_now - plan.old, offsets_now
        if not settings.push:
            return "disabled", zero, offsets_now
        if plan.refused:
            progress.message(f"push refused: {plan.refused}")
            fields = ({"reason": plan.refused} if plan.refusal is None
                      else plan.refusal.to_event())
            self.journal.event("push_refused", **fields, at=_now())
            return "refused", zero, offsets_now
        if not plan.anything:
            return "nothing_to_push", zero, offsets_now
        progress.stage("push")
        try:
            record = await execute_push(self.robot, plan, self.run_dir,
                                        self.robot_info.address, journal=self.journal)
        except ControllerError as exc:  # the controller's own limit: said once (swaps.py)
            refused = controller_limit_refusal(
                exc, self.run_dir,
                scenario=self.robot_info.scenario if self.robot_info.sim else None,
                refused_before=[str(e.get("reason")) for e in self.journal.events(
                    "push_refused") if e.get("rule") == "controller_limit"])
            if refused is None:
                raise
            self._controller_refusal = refused
            (self.run_dir / PUSH_FILE).unlink(missing_ok=True)  # its intent: never written
            progress.message(f"push refused: {refused.reason}")
            self.journal.event("push_refused", **refused.to_event(), by="controller",
                               at=_now())
            return "refused", zero, offsets_now
        labels = plan.display_names()
        progress.message("pushed zero offsets: " + ", ".join(
            f"{labels[j]} {math.degrees(o):+.4f}->{math.degrees(n):+.4f}"
            for j, (o, n) in enumerate(zip(plan.old, plan.new, strict=True)) if plan.pushed[j])
            + f" deg (rollback id {record.rollback_id})")
        return "pushed", plan.delta.copy(), plan.new.copy()

    def _verify_poses(self, plan: Plan) -> np.ndarray:
        """The plan's verification poses, with its further ones if it grew (more_poses)."""
        return plan.verify_poses(self.journal.last(MorePoses) is not None)

    def _pushed_ever(self) -> bool:
        """True if this run ever wrote the controller's offsets (a journaled `push`; an
        intent the controller refused, or that a resume settled as not written, wrote
        nothing). Called after `settle_push_intent`."""
        return self.journal.last(Pushed) is not None

    def _push_asked(self) -> bool:
        """True if this resume's command line asked for the push (--push or --force)."""
        return self.resume_overrides.push_asked

    def _asked(self) -> bool:
        """True if this resume asks for anything beyond finishing the run (an option that
        acts after the measurements: push, force, limits, verification, model)."""
        return self.resume_overrides.asked


def _now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="milliseconds")


def _initial_state(state: RobotState, offsets: np.ndarray) -> InitialState:
    return InitialState(state.robot, tuple(float(v) for v in state.q),
                        tuple(float(v) for v in offsets),
                        tuple(float(v) for v in state.q_min),
                        tuple(float(v) for v in state.q_max),
                        finite_or_none(float(state.extra.get("time", 0.0) or 0.0)),
                        state.camera)

