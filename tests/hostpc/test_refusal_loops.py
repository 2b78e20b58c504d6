"""Issue 24, item 6: a refusal's next command never sends the user back into the same
refusal (the loops a technician met after a motor swap): two joints over the default
limit, a declared swap over its own limit, a search that found nothing at the largest
limit, a --force that stuck to the run, a --separate resume that pushed, the controller's
own limit on a simulated run, and JOINTS_MISSING's advice."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from hostpc.calibrate.joint_status import JointSource
from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import PushIntent, PushRecord
from hostpc.calibrate.outcome import derive_outcome
from hostpc.calibrate.push import _limit_refusal
from hostpc.calibrate.resume import ResumeOverrides, persisted, resume_settings
from hostpc.calibrate.swaps import controller_limit_refusal, lost_plan_line
from hostpc.errors import ControllerError
from hostpc.methods.base import NullProgress, RunSettings

LABELS = tuple(f"q{j}" for j in range(1, 7))


def _refusal(deg: list[float], limits: list[float], max_correction: float = 2.0) -> str:
    delta = np.radians(deg)
    limit = np.asarray(limits, float)
    too_big = np.abs(delta) > np.radians(limit)
    return " ".join(_limit_refusal(delta, too_big, LABELS, max_correction, limit).next)


def test_two_joints_over_the_limit_are_declared_at_once_with_the_declared_ones() -> None:
    # J1 +2.3, J6 +2.1 deg: one command declares both (it used to name J1, then J6, ...)
    assert _refusal([2.3, 0, 0, 0, 0, 2.1], [2] * 6) == "calibrate --resume {run} --swapped J1,J6"
    # J1 declared already, J6 over the default: the next command keeps J1
    assert _refusal([2.3, 0, 0, 0, 0, 2.1], [45, 2, 2, 2, 2, 2]) == (
        "calibrate --resume {run} --swapped J1,J6")


def test_a_declared_swap_over_its_own_limit_gets_a_larger_swap_limit_not_force() -> None:
    assert _refusal([0, 0, 50.0, 0, 0, 0], [2, 2, 45, 2, 2, 2]) == (
        "calibrate --resume {run} --swap-limit 90")
    assert _refusal([0.3, 0, 0, 0, 0, 0], [0.1] * 6, 0.1) == "calibrate --resume {run} --force"


def test_the_lost_plan_never_names_a_joint_it_does_not_know_nor_repeats_the_largest_limit(
        ) -> None:
    undeclared = lost_plan_line(1, 24, ["no contact"], RunSettings(method="sphere_probe"),
                                "runs/x", staged=True)
    assert undeclared.endswith("hostpc calibrate --resume runs/x --swapped JN")
    assert "J1" not in undeclared and "replace JN" in undeclared
    at_90 = lost_plan_line(0, 24, [], RunSettings(method="sphere_probe", swapped=(1,),
                                                  swap_limit_deg=90.0), "runs/x", staged=True)
    assert "--swap-limit 180" in at_90
    at_180 = lost_plan_line(0, 24, [], RunSettings(method="sphere_probe", swapped=(1,),
                                                   swap_limit_deg=180.0), "runs/x", staged=True)
    assert "--swap-limit 180" not in at_180
    assert "J1 is probably not the joint whose motor was swapped" in at_180
    assert at_180.endswith("hostpc calibrate --resume runs/x --swapped JN --swap-limit 45")


def test_force_is_one_pushs_decision_and_a_separate_resume_pushes_only_when_asked(
        tmp_path: Path) -> None:
    journal = Journal(tmp_path)
    stored = RunSettings(method="stereo_target", force=True, swapped=(3,))
    again = resume_settings(stored, ResumeOverrides(swap_limit_deg=90.0), journal,
                            NullProgress())
    assert not again.force and again.swapped == (3,) and again.swap_limit_deg == 90.0
    forced = resume_settings(RunSettings(method="stereo_target"), ResumeOverrides(force=True),
                             journal, NullProgress())
    assert forced.force
    kept = persisted(forced, RunSettings(method="stereo_target"), ResumeOverrides(force=True))
    assert not kept.force  # run.json never keeps --force
    separate = ResumeOverrides(separate=("joint_compliance", "geometry"))
    measured = resume_settings(RunSettings(method="stereo_target"), separate, journal,
                               NullProgress())
    assert not measured.push
    assert persisted(measured, RunSettings(method="stereo_target"), separate).push
    asked = ResumeOverrides(separate=("joint_compliance", "geometry"), push=True)
    assert resume_settings(RunSettings(method="stereo_target"), asked, journal,
                           NullProgress()).push


class _Refused(ControllerError):
    def __init__(self) -> None:
        super().__init__("offsets differ from the original by more than 5.000 deg")
        self.reason = "offset_limit"


def test_the_controllers_limit_on_a_sim_run_names_the_scenario_key_and_never_repeats_itself(
        ) -> None:
    sim = controller_limit_refusal(_Refused(), "runs/x", scenario="/abs/runs/x/sim/scenario.json")
    assert sim is not None
    assert "server.offset_limit_rad in /abs/runs/x/sim/scenario.json" in sim.reason
    first = controller_limit_refusal(_Refused(), "runs/x")
    assert first is not None and "again" not in first.reason
    again = controller_limit_refusal(_Refused(), "runs/x", refused_before=[first.reason])
    assert again is not None
    assert "unchanged since the last refusal: it was not raised" in again.reason
    assert "pushing again meets the same refusal" in again.reason


def test_a_push_the_controller_refused_is_not_cut_short_on_resume(tmp_path: Path) -> None:
    from hostpc.calibrate.resume import settle_push_intent

    journal = Journal(tmp_path)
    old, new = np.zeros(6), np.full(6, math.radians(10.0))
    journal.append(PushIntent(PushRecord(old, new, None, (True,) * 6, "t")))
    journal.event("push_refused", reason="controller's own offset limit", rule="controller_limit",
                  next=["calibrate", "--resume", "{run}", "--push"])
    settle_push_intent(journal, tmp_path, "127.0.0.1:1", NullProgress(), old)
    assert not journal.events("note")
    assert not any("cut short" in str(e) for e in journal.timeline("note"))


def test_joints_missing_sends_to_a_reference_not_to_a_false_known() -> None:
    sources = tuple(JointSource(j, f"q{j}", "data") for j in range(2, 6))
    sources = (JointSource(1, "q1", "none", "unidentifiable with the target frame estimated",
                           "--known target"), *sources,
               JointSource(6, "q6", "none", "unidentifiable with the tool frame estimated",
                           "--known tool"))
    outcome = derive_outcome([], sources, run_dir="/abs/runs/x", finished=True,
                             required=range(1, 7),
                             new_run="--robot sim --method stereo_target --seed 7")
    assert outcome.verdict == "JOINTS_MISSING"
    # the surveyed frames, or a reference of a run that calibrated J1, J6; never a
    # reference of this run as the way (it keeps this robot's present J1, J6 zeros)
    assert outcome.next_command == (
        "hostpc calibrate --robot sim --method stereo_target --seed 7 --known target,tool "
        "--require-joints all (with the target and tool frame surveyed), or hostpc "
        "calibrate --robot sim --method stereo_target --seed 7 --reference "
        "CELL_REFERENCE.json --require-joints all (CELL_REFERENCE.json: hostpc reference "
        "record --run RUN of a run that calibrated J1, J6: with those frames surveyed, or "
        "on a robot whose zeros the maker's mastering set; recorded from this run "
        "(/abs/runs/x) it keeps this robot's present J1, J6 zeros and later runs restore "
        "J1, J6 to them)")
    assert "reference record --run /abs/runs/x" not in outcome.next_command


def test_a_swapped_joint_the_run_did_not_calibrate_is_never_sent_to_a_reference_of_this_run(
        ) -> None:
    """J1 declared swapped and not calibrated: its zero is unknown, and a reference recorded
    from this run would absorb its error into the target frame (a later false PASS)."""
    sources = (JointSource(1, "q1", "none", "unidentifiable with the target frame estimated",
                           "--known target (or a cell reference that fixes the target "
                           "frame)"),
               *(JointSource(j, f"q{j}", "data") for j in range(2, 6)),
               JointSource(6, "q6", "none", "unidentifiable with the tool frame estimated",
                           "--known tool"))
    new_run = "--robot sim --method stereo_target --swapped J1 --seed 7"
    outcome = derive_outcome([], sources, run_dir="/abs/runs/x", finished=True,
                             required=(1,), new_run=new_run, swapped=(1,))
    assert outcome.verdict == "JOINTS_MISSING"
    assert outcome.next_command is not None
    assert "reference record" not in outcome.next_command
    assert "record the cell's reference" not in outcome.headline
    assert outcome.next_command == (
        f"hostpc calibrate {new_run} --reference REFERENCE_FROM_BEFORE_THE_SWAP.json "
        "--require-joints 1, or "
        f"hostpc calibrate {new_run} --known target --require-joints 1 (with the target "
        "frame surveyed), or set J1 with the robot maker's zeroing procedure")
    assert "J1 declared swapped and not calibrated: its zero is unknown" in outcome.headline
    # the swap declared on a joint the run did calibrate: its zero is known, as before
    calibrated = derive_outcome([], sources, run_dir="/abs/runs/x", finished=True,
                                required=(1, 6), new_run=new_run, swapped=(2,))
    assert calibrated.next_command is not None
    assert calibrated.next_command.startswith(f"hostpc calibrate {new_run} --known target,tool")


def test_a_fit_that_failed_with_holds_and_priors_names_them_in_the_refusal() -> None:
    sources = (JointSource(1, "q1", "data"),
               JointSource(2, "q2", "prior", "determined by its --prior"),
               JointSource(3, "q3", "hold", "held at its nominal value by --hold"),
               *(JointSource(j, f"q{j}", "data") for j in range(4, 7)))
    refused = {"event": "push_refused", "reason": "the model does not explain the "
               "measurements", "rule": "model", "next": ["diagnose", "{run}/dataset.json"]}
    outcome = derive_outcome([refused], sources, run_dir="runs/x", finished=True)
    assert outcome.verdict == "REFUSED"
    assert outcome.headline.endswith("; the fit failed with J3 held and a prior on J2: a "
                                     "likely cause; run again without them or check them")
    # a limit refusal is not a failed fit: the holds are not its cause
    limit = {**refused, "rule": "correction_limit", "next": ["calibrate", "--force"]}
    assert "held" not in derive_outcome([limit], sources, run_dir="runs/x",
                                        finished=True).headline


def test_the_controllers_limit_suggests_a_value_from_the_largest_fitted_correction(
        tmp_path: Path) -> None:
    """A 10 deg J1 correction (0.1745 rad): raise the limit to 0.22 rad, not 3.2 rad."""
    fit = {"parameters": {
        "joint_offsets.q1": {"value": math.radians(10.0), "unit": "rad"},
        "joint_offsets.q2": {"value": -math.radians(0.5), "unit": "rad"},
        "tool.x": {"value": 0.9, "unit": "m"}}}
    (tmp_path / "fit.json").write_text(json.dumps(fit))
    refusal = controller_limit_refusal(_Refused(), tmp_path, scenario="/abs/scenario.json")
    assert refusal is not None
    assert "3.2 rad" not in refusal.reason
    assert ("raise it there above the largest correction (10 deg, 0.175 rad), e.g. 0.22 rad"
            in refusal.reason)


def test_a_separation_with_its_poses_lost_or_no_dof_left_is_not_tested(tmp_path: Path) -> None:
    from hostpc.calibrate.separate import SeparationPlan, untestable
    from hostpc.methods.base import SampleRecord

    journal = Journal(tmp_path)
    planned = SeparationPlan(("joint_compliance", "geometry"), 100, np.zeros((5, 6)), {})
    journal.record(SampleRecord("fit", 100, True, {"q": [0.0] * 6}))
    for index in range(101, 105):
        journal.record(SampleRecord("fit", index, False, reason="no contact"))
    lost = untestable(journal, planned, dof=40)
    assert lost is not None and "4 of 5 separating poses were lost" in lost
    assert "could not be done" in lost
    for index in range(101, 105):
        journal.record(SampleRecord("fit", index, True, {"q": [0.0] * 6}))
    assert untestable(journal, planned, dof=40) is None
    no_dof = untestable(journal, planned, dof=0)
    assert no_dof is not None and "no degree of freedom left" in no_dof
