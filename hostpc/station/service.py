"""The station service: the PLC's commands in, one calibration at a time, results out.

States (register STATE): IDLE -> (START with a serial) -> RUNNING -> PASS | FAIL | ERROR
-> (ACKNOWLEDGE) -> IDLE. Every run is a `hostpc calibrate` child process in its own run
folder; its result is archived and written to the result registers; any failure is a
result code, never a dead service. The run in progress is recorded in `current.json`
under the runs folder, so a restarted station resumes it (`hostpc calibrate --resume`)
before taking a new command. SIGTERM stops the station gracefully: the child is
interrupted at a safe point and stays resumable.

Truth: STATE, RESULT_CODE and the joint registers come from the run's outcome
(result.json "outcome", hostpc.calibrate.outcome): PASS only for the verdict PASS.
A PLC abort once the run has written (or started writing) the controller's offsets is
DEFERRED: the child is not interrupted, the verification of the pushed offsets finishes,
and the registers show the real verdict (the log says the abort was deferred). If the
child ends anyway with a push not followed by a result (killed, link lost), the station
resumes it (`--resume`, up to resume_attempts; a simulated robot's with `--push`, its
controller ended with the run) so the offsets get verified; current.json stays while the
controller may hold unverified offsets: that run is PENDING, and a START of another robot
is refused (result code 24) until it is settled (START of the same serial or a station
restart resumes it; a resume or rollback by hand shows in its journal). What a resume
finds the controller holding decides the step (current.json "held"): its previous
offsets again (push lost) -> the station pushes them again (`--push`) and names that
push; neither its previous nor its pushed offsets -> no resume settles it: archived
ERROR, and the PLC's ACKNOWLEDGE releases it (current.json removed). A run without a
result that pushed is reported pushed, with its journal's offsets (hostpc.archive). The
result on the registers is the run's archived record, kept in `last_outcome.json` under
the runs folder until the PLC acknowledges it (a station restarted before ACKNOWLEDGE
serves it again) and following the record: a revision (a rollback, a resume with --db)
is served as the archive has it now.

Reasons: a run that does not PASS has a one-line reason (calibrate's own error line, the
outcome's headline, or the station's: aborted, cannot start, not archived). It goes to the
station log, the live page (`status.reason`), the archive (the run's `reason`) and the
registers (REASON_CODE, REASON). Every concluded run is archived, also one that failed
before its run folder held anything, and has a report.html: calibrate's own, or the
station's (hostpc.station.run_report) when the run ended before writing one.

What the live page shows is `status`, exactly the station's state: a run's progress and
output line only while it runs, its result (verdict, reason, report) until the PLC
acknowledges it, nothing of it once IDLE.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import uuid
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

from hostpc.archive import open_archive, record_from_run
from hostpc.archive.database import Archive
from hostpc.archive.records import (
    JointOffset,
    outcome_of,
    read_result,
    verdict_of,
    verify_figures,
)
from hostpc.archive.rows import StoredRun
from hostpc.calibrate.next_commands import rollback_command
from hostpc.calibrate.run_result import RunResult
from hostpc.errors import InputError, ZerocalError
from hostpc.files import write_json_atomic
from hostpc.station import registers as reg
from hostpc.station.config import StationConfig
from hostpc.station.plc import PlcServer
from hostpc.station.run_report import write_station_report
from hostpc.station.runner import (
    OTHER,
    PREVIOUS,
    ChildRun,
    calibrate_command,
    controller_held,
    push_in_flight,
    push_not_stored,
    resume_text,
    start_child,
)
from hostpc.station.status import CurrentRun, RecentRun, StationStatus

logger = logging.getLogger("hostpc.station")
run_log = logging.getLogger("hostpc.station.run")
"""The lines of the station's runs and their reasons: whole (hostpc.station's own lines,
which a PLC can cause many of, are rate-limited and cut; a run's line is never cut, so its
next command stays whole)."""
EXIT_CONNECTION = 3  # `hostpc calibrate`: the controller could not be reached / link lost
FOLLOW_INTERVAL_S = 1.0
"""How often the result on the registers is checked against its archived record (s)."""


class Station:
    def __init__(self, config: StationConfig, source: str = "station config"):
        self.config = config
        self.source = source  # the config file, as one-line errors name it
        self.runs_dir = config.path(config.runs_dir)
        self.current_file = self.runs_dir / "current.json"
        self.last_outcome_file = self.runs_dir / "last_outcome.json"
        self.plc = PlcServer(config.modbus.host, config.modbus.port)
        self.status = StationStatus()
        self.archive: Archive | None = None
        self._child: ChildRun | None = None
        self._stopping = asyncio.Event()
        self._aborted = False
        self._child_error = ""
        self._served: tuple[int, int] | None = None  # (archive id, revision) on the registers
        self._refusal_logged = ""  # the pending run whose refusals the log has said whole
        self.modbus_address: tuple[str, int] | None = None

    # -- life cycle -------------------------------------------------------------------
    async def open(self) -> None:
        """Listen for the PLC, then open the archive (the station creates it if missing)
        and the runs folder; InputError naming the config key (`modbus`, `db`, `runs_dir`)
        if one fails, nothing created then."""
        try:
            address = await self.plc.start()
        except OSError as exc:
            raise InputError(f"{self.source}: modbus: {self.config.modbus.host}:"
                             f"{self.config.modbus.port}: cannot listen "
                             f"({exc.strerror or exc})") from None
        try:
            self.archive = await asyncio.to_thread(open_archive, self.config.database_url())
            self.runs_dir.mkdir(parents=True, exist_ok=True)
        except (ZerocalError, OSError) as exc:
            await self.close()
            key = "db" if isinstance(exc, ZerocalError) else "runs_dir"
            raise InputError(f"{self.source}: {key}: {exc}") from None
        self.modbus_address = address
        logger.info("PLC registers on %s:%d", *address)

    async def run(self, ready: asyncio.Event | None = None) -> None:
        """Serve until `stop()` (opening first unless `open()` was called); resumes an
        interrupted run first."""
        if self.modbus_address is None:
            await self.open()
        self._publish_state(reg.State.IDLE)
        heartbeat = asyncio.create_task(self._heartbeat())
        try:
            if ready is not None:
                ready.set()
            if self.current_file.exists():
                await self._resume_interrupted()
            else:
                self._serve_unacknowledged()
            followed = 0.0
            while not self._stopping.is_set():
                await self._poll_command()
                now = asyncio.get_running_loop().time()
                if now - followed >= FOLLOW_INTERVAL_S:
                    followed = now
                    await self._follow_archive()
                with contextlib.suppress(TimeoutError):  # a cancel lost (gh-86296) with
                    # the stop event (its only result) ends the loop all the same
                    await asyncio.wait_for(self._stopping.wait(), 0.1)
        finally:
            heartbeat.cancel()
            await self.close()

    async def close(self) -> None:
        """Stop listening and close the archive (after `open`, without `run`)."""
        await self.plc.close()
        if self.archive is not None:
            await asyncio.to_thread(self.archive.close)
            self.archive = None

    def stop(self) -> None:
        """Graceful stop: interrupt the child at a safe point (it stays resumable)."""
        self._stopping.set()
        if self._child is not None:
            self._child.interrupt()

    async def _heartbeat(self) -> None:
        while True:
            self.plc.set(reg.HEARTBEAT, (self.plc.values[reg.HEARTBEAT] + 1) & 0xFFFF)
            await asyncio.sleep(1.0)

    def _publish_state(self, state: reg.State) -> None:
        self.plc.set(reg.STATE, int(state))
        self.status.state = state.name

    # -- commands ---------------------------------------------------------------------
    async def _poll_command(self) -> None:
        command = self.plc.values[reg.COMMAND]
        if command == reg.Command.NONE:
            return
        self.plc.set(reg.COMMAND, reg.Command.NONE)
        state = reg.State(self.plc.values[reg.STATE])
        if command == reg.Command.START and state == reg.State.IDLE:
            self.plc.set(reg.COMMAND_IGNORED, 0)
            await self._start_run()
        elif command == reg.Command.ACKNOWLEDGE and state in (
                reg.State.PASS, reg.State.FAIL, reg.State.ERROR):
            self.plc.set_many(reg.outcome_registers(reg.RunOutcome(reg.State.IDLE, 0)))
            self.plc.set(reg.PROGRESS, 0)
            self.plc.set(reg.COMMAND_IGNORED, 0)
            self.status.clear_run()
            self._served = None
            self._publish_state(reg.State.IDLE)
            self.last_outcome_file.unlink(missing_ok=True)  # acknowledged: not served again
            self._release_unsettleable()
        else:  # not taken: the PLC reads so in COMMAND_IGNORED, not only the log
            self.plc.set(reg.COMMAND_IGNORED, command)
            logger.warning("command %d ignored in state %s (COMMAND_IGNORED = %d)%s",
                           command, state.name, command,
                           ": acknowledge the result first (COMMAND = 3)"
                           if state != reg.State.IDLE else "")

    async def _start_run(self) -> None:
        serial = reg.decode_text(self.plc.values[reg.SERIAL:reg.SERIAL + reg.SERIAL_LENGTH])
        model = reg.decode_text(self.plc.values[reg.MODEL:reg.MODEL + reg.MODEL_LENGTH])
        if not serial:
            reason = (f"start refused: no robot serial number in registers {reg.SERIAL}.."
                      f"{reg.SERIAL + reg.SERIAL_LENGTH - 1}")
            self.status.clear_run()
            self._finish(reg.RunOutcome(reg.State.ERROR, reg.RESULT_NO_SERIAL, reason=reason))
            logger.error("%s", reason)
            return
        pending = self._pending_run()
        if pending is not None:
            if pending.serial == serial and not self._needs_rollback(Path(pending.run_dir)):
                # the same robot again: verify its push first
                run_log.warning("START %s: resuming its run %s first (%s)", serial,
                                pending.run_dir,
                                "its push was lost: pushing again" if pending.held == PREVIOUS
                                else "its pushed offsets are not verified")
                current = dataclasses.replace(pending, attempts=0)
                self._write_current(current)
                await self._execute(current, resume=True)
                return
            reason = (f"start of {serial} refused: the run of {pending.serial} pushed "
                      f"offsets that are NOT {self._unsettled(Path(pending.run_dir))}; "
                      + self._pending_text(pending))
            self.status.clear_run()
            self.status.serial, self.status.model = serial, model
            self._finish(reg.RunOutcome(reg.State.ERROR, reg.RESULT_PUSH_PENDING,
                                        reason=reason))
            if self._refusal_logged != pending.run_dir:  # whole, once per pending run
                self._refusal_logged = pending.run_dir
                run_log.error("%s", reason)
            else:  # again: a PLC can repeat it; the rate-limited logger, one short line
                logger.error("start of %s refused: the pending run %s (see above)", serial,
                             pending.run_dir)
            return
        stamp = datetime.now(UTC)
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in serial)
        run_dir = self.runs_dir / f"{safe}-{stamp:%Y%m%dT%H%M%S%f}"
        current = CurrentRun(run_uid=str(uuid.uuid4()), serial=serial, model=model,
                             run_dir=str(run_dir), started_at=stamp.isoformat())
        self._write_current(current)
        await self._execute(current, resume=False)

    def _pending_run(self) -> CurrentRun | None:
        """The concluded run whose pushed offsets are not verified (current.json kept for
        it), or None; a pending run settled by hand since (resumed or rolled back: its
        journal says so) is pending no more."""
        try:
            pending = CurrentRun.from_json(json.loads(self.current_file.read_text()))
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            run_log.error("%s is damaged: no pending run is kept", self.current_file)
            self.current_file.unlink(missing_ok=True)
            return None
        if push_in_flight(Path(pending.run_dir)):
            return pending
        run_log.info("the pending run of %s in %s was settled by hand (its journal has a "
                     "result or a rollback since)", pending.serial, pending.run_dir)
        self.current_file.unlink(missing_ok=True)
        return None

    def _needs_rollback(self, run_dir: Path) -> bool:
        """True if the run's push in flight is one the controller did not store as asked
        (a real controller: `push_not_stored`): no resume settles it, only a rollback, so
        the station resumes it never and says so (docs/station.md)."""
        return self.config.robot != "sim" and push_not_stored(run_dir)

    def _unsettled(self, run_dir: Path) -> str:
        """What is wrong with a pending run's pushed offsets, in a few words."""
        return ("stored as asked (push failed)" if self._needs_rollback(run_dir)
                else "verified")

    def _pending_text(self, pending: CurrentRun) -> str:
        """The one action that settles a run pending with pushed offsets not verified, as
        what the controller holds decides (`pending.held`, its last resume's finding)."""
        serial, run_dir = pending.serial, Path(pending.run_dir)
        if self._needs_rollback(run_dir):
            return ("no resume settles it (the controller holds other offsets than the run "
                    "pushed: a resume meets them again), and the station starts no robot "
                    "until it is rolled back: "
                    f"{rollback_command(run_dir, self.config.database_url())}, then START "
                    f"{serial} again")
        if pending.held == OTHER:
            return ("the controller holds neither the run's previous nor its pushed "
                    "offsets (it restarted, or someone wrote them): no resume settles the "
                    "run; ACKNOWLEDGE (COMMAND = 3) releases it (archived ERROR, the "
                    f"controller's offsets left as they are), then START {serial} again "
                    "for a new run")
        if pending.held == PREVIOUS:
            return ("the controller has the run's previous offsets again (push lost); the "
                    "station starts no other robot until it is settled: START "
                    f"{serial} again to push them again and verify (its robot in the "
                    "cell), or by hand: "
                    f"{resume_text(self.config, run_dir, push_again=True)}")
        undo = ("" if self.config.robot == "sim" else
                f"; undo it: {rollback_command(run_dir, self.config.database_url())}")
        return (f"the station starts no other robot until it is settled: START {serial} "
                f"again to resume it (its robot in the cell), or resume it by hand: "
                f"{resume_text(self.config, run_dir)}{undo}")

    def _release_unsettleable(self) -> None:
        """On ACKNOWLEDGE: release a pending run no resume settles (its controller holds
        neither its previous nor its pushed offsets; the archive has it ERROR): the
        station takes other robots again."""
        pending = self._pending_run()
        if pending is None or pending.held != OTHER:
            return
        self.current_file.unlink(missing_ok=True)
        run_log.warning("the pending run of %s in %s released by ACKNOWLEDGE: its controller "
                        "holds neither its previous nor its pushed offsets (archived ERROR); "
                        "the station takes other robots again", pending.serial,
                        pending.run_dir)

    async def _resume_interrupted(self) -> None:
        try:
            current = CurrentRun.from_json(json.loads(self.current_file.read_text()))
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            logger.error("%s is damaged: the interrupted run is not resumed", self.current_file)
            self.current_file.unlink(missing_ok=True)
            return
        if self._needs_rollback(Path(current.run_dir)):  # a resume would fail on it again
            self._refusal_logged = current.run_dir
            run_log.error("the run of %s in %s is not resumed: its pushed offsets are NOT "
                          "%s; %s", current.serial, current.run_dir,
                          self._unsettled(Path(current.run_dir)),
                          self._pending_text(current))
            self._serve_unacknowledged()
            return
        logger.info("resuming the interrupted run of %s in %s", current.serial,
                    current.run_dir)
        await self._execute(current, resume=Path(current.run_dir).exists())

    # -- one run ----------------------------------------------------------------------
    def _write_current(self, current: CurrentRun) -> None:
        write_json_atomic(self.current_file, current.to_json())

    async def _execute(self, current: CurrentRun, resume: bool) -> None:
        serial, run_dir = current.serial, Path(current.run_dir)
        self.status.clear_run()
        self.status.serial, self.status.model = serial, current.model
        self.status.run_dir, self.status.progress = str(run_dir), 0
        self.plc.set(reg.RUN_COUNTER, (self.plc.values[reg.RUN_COUNTER] + 1) & 0xFFFF)
        self.plc.set(reg.PROGRESS, 0)
        self._publish_state(reg.State.RUNNING)
        self._aborted, self._child_error = False, ""
        code, current = await self._attempts(current, run_dir, resume)
        if self._stopping.is_set() and not self._aborted:
            logger.info("station stopping: run %s left resumable", run_dir)
            return  # current.json stays: the next start resumes it
        await self._conclude(current, run_dir, code)

    async def _attempts(self, current: CurrentRun, run_dir: Path, resume: bool
                        ) -> tuple[int, CurrentRun]:
        """Run the child, and resume it while that may settle the run: the exit code and
        the run as current.json has it now (its resumes, what the controller holds)."""
        while True:
            try:
                command = calibrate_command(self.config, run_dir, current.serial, resume,
                                            push_again=current.held == PREVIOUS)
            except (ZerocalError, OSError) as exc:
                self._child_error = f"the calibration cannot start: {exc}"
                return reg.RESULT_STATION_ERROR, current
            log_path = (run_dir.parent / f"{run_dir.name}.log")
            self.status.last_line = ""  # (a resume: the last child's hint is acted on)
            child, done = await start_child(command, log_path, self._on_progress)
            self._child = child
            watcher = asyncio.create_task(self._watch_abort(child))
            try:
                code = await done
            finally:
                watcher.cancel()
                self._child = None
            self._child_error = child.error
            in_flight = push_in_flight(run_dir)
            if self._aborted and not in_flight:
                return reg.RESULT_ABORTED, current
            if self._stopping.is_set():
                return code, current
            held = controller_held(code, child.error) if in_flight else ""
            if held != current.held:  # what the controller holds decides the next step
                current = dataclasses.replace(current, held=held)
                self._write_current(current)
            if held == PREVIOUS and "--push" not in command and self.config.resume_attempts \
                    and not self._needs_rollback(run_dir):
                # the one step that settles it; not a resume attempt: a resume that pushes
                # again never finds the push lost
                run_log.warning("push lost during the run of %s (the controller has the "
                                "run's previous offsets again): pushing them again and "
                                "verifying", current.serial)
                resume, self._aborted = True, False
                continue
            if held != OTHER and (code == EXIT_CONNECTION or in_flight) and run_dir.exists() \
                    and current.attempts < self.config.resume_attempts \
                    and not self._needs_rollback(run_dir):  # a resume fails on it again
                current = dataclasses.replace(current, attempts=current.attempts + 1)
                self._write_current(current)
                why = ("link lost" if not in_flight else
                       "the run ended with pushed offsets not verified (its simulated "
                       "controller with it: the resume pushes again)"
                       if self.config.robot == "sim" else
                       "the run ended with pushed offsets not verified")
                run_log.warning("%s during the run of %s: resuming (attempt %d of %d)", why,
                               current.serial, current.attempts,
                               self.config.resume_attempts)
                resume, self._aborted = True, False
                continue
            return code, current

    async def _watch_abort(self, child: ChildRun) -> None:
        while True:
            command = self.plc.values[reg.COMMAND]
            if command not in (reg.Command.NONE, reg.Command.ABORT):  # not while running
                self.plc.set(reg.COMMAND, reg.Command.NONE)
                self.plc.set(reg.COMMAND_IGNORED, command)
                logger.warning("command %d ignored while running (COMMAND_IGNORED = %d)",
                               command, command)
            if command == reg.Command.ABORT:
                self.plc.set(reg.COMMAND, reg.Command.NONE)
                self.plc.set(reg.COMMAND_IGNORED, 0)
                if push_in_flight(Path(self.status.run_dir)):
                    logger.warning("PLC abort deferred: the run has written the controller's "
                                   "offsets; their verification finishes first")
                else:
                    self._aborted = True
                    logger.warning("PLC abort: interrupting the run")
                    child.interrupt()
            await asyncio.sleep(0.05)

    def _on_progress(self, progress: int, line: str) -> None:
        self.status.progress, self.status.last_line = progress, line
        self.plc.set(reg.PROGRESS, progress)

    async def _conclude(self, current: CurrentRun, run_dir: Path, code: int) -> None:
        serial = current.serial
        started_at = datetime.fromisoformat(current.started_at)
        result = _read_result(run_dir)
        pending = current if push_in_flight(run_dir) else None  # pushed, not verified
        reason = self._reason(code, result, run_dir, serial, pending)
        log_path = run_dir.parent / f"{run_dir.name}.log"
        if not (run_dir / "report.html").is_file():  # ended before calibrate wrote one
            try:
                write_station_report(
                    run_dir / "report.html", serial=serial, model=current.model,
                    station=self.config.station, started_at=started_at.isoformat(),
                    verdict=verdict_of(result, code), result_code=code,
                    reason=reason, log_path=log_path)
            except OSError as exc:
                logger.error("run %s: no report written (%s)", run_dir, exc.strerror or exc)
        archive_id = None
        record = None
        stored = None
        try:
            record = record_from_run(
                run_dir, serial=serial, model=current.model,
                station=self.config.station, exit_code=code, run_uid=current.run_uid,
                started_at=started_at, reason=reason)
            assert self.archive is not None
            archive_id = await asyncio.to_thread(self.archive.add, record)
            stored = await asyncio.to_thread(self.archive.run, archive_id)
        except ZerocalError as exc:
            logger.error("run %s not archived: %s", run_dir, exc)
            if not code:
                code, reason = reg.RESULT_ARCHIVE_FAILED, f"not archived: {exc}"
        if stored is not None:  # the registers say what the archive holds
            outcome = archived_outcome(stored)
            self._served = (stored.run.id, stored.run.revision)
        else:
            self._served = None
            outcome = reg.RunOutcome(reg.State.ERROR, code, reason=reason)
            if record is not None and code != reg.RESULT_ARCHIVE_FAILED:
                outcome = run_outcome(record.verdict, code, record.push_status,
                                      record.largest_correction_deg, record.offsets,
                                      record.result, None, reason)
        self.status.last_line = ""  # the run's output: acted on, the result says the rest
        self.status.archive_id = archive_id
        self.status.report = (f"/runs/{archive_id}/report.html"
                              if archive_id is not None and record is not None
                              and record.report_path else "")
        self._finish(outcome)
        if pending is not None:
            run_log.error("run %s ended with pushed offsets not %s: current.json kept (%s); "
                          "%s", run_dir, self._unsettled(run_dir),
                          "until it is rolled back" if self._needs_rollback(run_dir) else
                          "until ACKNOWLEDGE releases it" if pending.held == OTHER else
                          "the next station start resumes it", self._pending_text(pending))
        else:
            self.current_file.unlink(missing_ok=True)
        self.status.runs_done += 1
        self.status.recent = ([RecentRun(serial, outcome.state.name, outcome.result_code,
                                         archive_id, str(run_dir), outcome.reason)]
                              + self.status.recent)[:20]
        if outcome.reason:
            run_log.error("run of %s: %s (result code %d, archive id %s): %s", serial,
                          outcome.state.name, outcome.result_code, archive_id, outcome.reason)
        else:
            run_log.info("run of %s: %s (result code %d, archive id %s)", serial,
                         outcome.state.name, outcome.result_code, archive_id)

    async def _follow_archive(self) -> None:
        """The result on the registers follows its archived record: a run revised since
        (`hostpc rollback --run DIR --db URL`, a resume by hand with --db) is served as the
        archive has it now, never the outcome it had."""
        if self._served is None or self.archive is None:
            return
        archive_id, revision = self._served
        try:  # its revisions first (small rows); the run with its documents if revised
            revisions = await asyncio.to_thread(self.archive.revisions, archive_id)
            if not revisions or revisions[-1].revision == revision:
                return
            stored = await asyncio.to_thread(self.archive.run, archive_id)
        except ZerocalError as exc:
            logger.error("archived run %d cannot be read: %s", archive_id, exc)
            return
        outcome = archived_outcome(stored)
        self._served = (archive_id, stored.run.revision)
        self._finish(outcome)
        self.status.recent = [dataclasses.replace(r, verdict=outcome.state.name,
                                                  result_code=outcome.result_code,
                                                  reason=outcome.reason)
                              if r.archive_id == archive_id else r
                              for r in self.status.recent]
        run_log.warning("run of %s (archive id %d) was revised (revision %d, verdict %s): "
                        "now serving %s (result code %d): %s", stored.run.serial, archive_id,
                        stored.run.revision, stored.run.verdict, outcome.state.name,
                        outcome.result_code, outcome.reason)

    def _reason(self, code: int, result: RunResult | None, run_dir: Path, serial: str,
                pending: CurrentRun | None) -> str:
        """One line: why the run with exit `code` and `result` (result.json) did not PASS,
        and the station's next step (empty when it passed)."""
        outcome = outcome_of(result)
        if code == reg.RESULT_ABORTED:
            return "aborted by the PLC before the push"
        if code == 0 and outcome is not None and outcome.verdict == "PASS":
            return ""
        text = self._child_error or (outcome.headline if outcome is not None else "")
        if not text and code:
            text = f"hostpc calibrate ended with exit code {code}"
        step = self._next_step(outcome.verdict if outcome is not None else None, result,
                               run_dir, serial, pending)
        return " ".join(f"{text}; station: {step}".split() if step else text.split())

    def _next_step(self, verdict: str | None, result: RunResult | None, run_dir: Path,
                   serial: str, pending: CurrentRun | None) -> str:
        """The station's own next step of a run that did not PASS (empty: calibrate's
        reason says it): its commands as a station's technician types them; of a `pending`
        run (pushed, not verified), the one that settles it."""
        if pending is not None:
            if pending.held == OTHER and not self._needs_rollback(run_dir):
                return self._pending_text(pending)
            return f"pushed offsets NOT {self._unsettled(run_dir)}; {self._pending_text(pending)}"
        if verdict == "FAIL":
            if self.config.robot == "sim":
                return ("the simulated controller ended with the run (nothing to roll "
                        f"back): START {serial} again")
            return (f"while {serial} is still the robot on this station: "
                    f"{rollback_command(run_dir, self.config.database_url())} (its previous "
                    f"offsets back), then START {serial} again; once another robot was "
                    "started, do not roll back (it would refuse: the controller holds "
                    "that robot's offsets)")
        block = result.outcome if result is not None else None
        next_command = str(block.get("next_command") or "") if block else ""
        if verdict == "JOINTS_MISSING" and "--reference" in next_command:
            reference = Path(f"{str(run_dir).rstrip('/')}.cell_ref.json")
            args = f'"--reference", "{reference}"'
            if (run_dir / "rig.json").is_file():  # its camera frame holds for this rig only
                args += f', "--rig", "{reference.with_suffix(".rig.json")}"'
            return (f"for this station: record the cell's reference from a run on a robot "
                    "whose zeros are known good (mastered by the maker's procedure, or "
                    "calibrated with its frames surveyed: --known): hostpc reference record "
                    f"--run THAT_RUN --out {reference}; one recorded from this run keeps "
                    "this robot's present J1/J6 zeros for every later robot (JOINTS_AS_FOUND "
                    f"then says so); put {args} in calibrate_args of {self.source} and "
                    "restart the station")
        return ""

    def _finish(self, outcome: reg.RunOutcome) -> None:
        self.plc.set_many(reg.outcome_registers(outcome))
        self.plc.set(reg.PROGRESS, 100 if outcome.state != reg.State.ERROR else
                     self.plc.values[reg.PROGRESS])
        self.status.result_code = outcome.result_code
        self.status.reason = outcome.reason
        self.status.reason_code = int(reg.reason_of(outcome.state, outcome.result_code,
                                                     outcome.reason))
        self.status.progress = self.plc.values[reg.PROGRESS]
        self._publish_state(outcome.state)
        registers = {**reg.outcome_registers(outcome), reg.PROGRESS: self.plc.values[reg.PROGRESS]}
        write_json_atomic(self.last_outcome_file,  # served again after a restart until ACK
                          {"registers": {str(k): v for k, v in registers.items()},
                           "result_code": outcome.result_code, "reason": outcome.reason,
                           "serial": self.status.serial, "model": self.status.model,
                           "archive_id": self.status.archive_id,
                           "revision": self._served[1] if self._served else None,
                           "report": self.status.report})

    def _serve_unacknowledged(self) -> None:
        """After a restart: the last result the PLC has not acknowledged, on the registers
        again (last_outcome.json)."""
        try:
            saved = json.loads(self.last_outcome_file.read_text())
            registers = {int(k): int(v) for k, v in saved["registers"].items()}
            state = reg.State(registers[reg.STATE])
        except FileNotFoundError:
            return
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            logger.error("%s is damaged: the last result is not served again",
                         self.last_outcome_file)
            return
        self.plc.set_many(registers)
        self.status.result_code = saved.get("result_code")
        self.status.reason = str(saved.get("reason") or "")
        self.status.reason_code = registers.get(reg.REASON_CODE, 0)
        self.status.serial = str(saved.get("serial") or "")
        self.status.model = str(saved.get("model") or "")
        self.status.archive_id = saved.get("archive_id")
        self.status.report = str(saved.get("report") or "")
        self._publish_state(state)
        archive_id, revision = saved.get("archive_id"), saved.get("revision")
        if isinstance(archive_id, int):  # follow its record: revised since, served so
            self._served = (archive_id, revision if isinstance(revision, int) else 0)
        logger.info("serving the unacknowledged result again: %s (result code %s)",
                    state.name, registers.get(reg.RESULT_CODE))


def run_outcome(verdict: str, exit_code: int, push_status: str,
                largest_correction_deg: float | None, offsets: Sequence[JointOffset],
                result: RunResult | None, archive_id: int | None, reason: str
                ) -> reg.RunOutcome:
    """The result registers of a concluded run as its record says: STATE PASS only for
    the verdict PASS, ERROR for a run that did not finish (it may still have pushed: the
    pushed flag and joints, from its journal), FAIL otherwise."""
    state = (reg.State.PASS if verdict == "PASS" else
             reg.State.ERROR if verdict == "ERROR" else reg.State.FAIL)
    verify = verify_figures(result)
    bits = reg.outcome_bits(outcome_of(result), push_status,
                            [o.joint for o in offsets if o.pushed])
    return reg.RunOutcome(
        state, exit_code, largest_correction_deg=largest_correction_deg,
        verify_statistic=verify.statistic, verify_p_value=verify.p_value,
        verify_dof=verify.dof, archive_id=archive_id,
        reason="" if state == reg.State.PASS else reason, **bits._asdict())


def archived_outcome(stored: StoredRun) -> reg.RunOutcome:
    """The result registers of an archived run as its record holds it now (its current
    revision); its reason: the archived one, else its outcome's headline."""
    run = stored.run
    outcome = outcome_of(stored.result)
    reason = run.reason or (outcome.headline if outcome is not None else "")
    return run_outcome(run.verdict, run.exit_code, run.push_status,
                       run.largest_correction_deg, run.offsets, stored.result, run.id, reason)


def _read_result(run_dir: Path) -> RunResult | None:
    """The run's result.json, or None (none yet, or unreadable: the archive says why)."""
    try:
        return read_result(run_dir / "result.json")
    except InputError:
        return None
