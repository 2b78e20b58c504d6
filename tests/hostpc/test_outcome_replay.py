"""The run's outcome derived from its journal (hostpc.calibrate.outcome.derive_outcome):
what a resume changes and what it must not."""

from __future__ import annotations

from hostpc.calibrate.joint_status import JointSource
from hostpc.calibrate.outcome import derive_outcome

SOURCES = tuple(JointSource(j, f"q{j}", "data") for j in range(1, 7))
PUSH = {"event": "push", "at": "t1", "new_offsets": [0.01] * 6, "previous_offsets": [0.0] * 6,
        "pushed": [True] * 6, "rollback_id": "rb-1"}
VERIFY_PASS = {"event": "verify", "at": "t2", "verdict": "PASS", "p_value": 0.5,
               "offsets": [0.01] * 6}


def outcome_of(*events: dict[str, object]) -> str:
    return derive_outcome(list(events), SOURCES, run_dir="runs/x", finished=True).verdict


def test_a_refusal_speaks_for_its_attempt_only() -> None:
    refused = {"event": "push_refused", "at": "t1", "reason": "the target frame moved"}
    resumed = {"event": "resumed", "at": "t2"}
    assert outcome_of(refused) == "REFUSED"
    # the resume re-decides the push: with the push off it is NOT_PUSHED, not the old refusal
    assert outcome_of(refused, resumed) == "NOT_PUSHED"
    # refused again on the resume: the resumed attempt's own refusal
    assert outcome_of(refused, resumed, refused) == "REFUSED"


def test_a_push_and_a_rollback_outlive_a_resume() -> None:
    resumed = {"event": "resumed", "at": "t3"}
    assert outcome_of(PUSH, VERIFY_PASS, resumed) == "PASS"
    rollback = {"event": "rollback", "at": "t4", "how": "hostpc rollback"}
    assert outcome_of(PUSH, VERIFY_PASS, rollback, resumed) == "ROLLED_BACK"


def test_a_correction_beyond_the_limit_suggests_declaring_the_swap_not_force() -> None:
    swap = {"event": "push_refused", "at": "t1", "reason": (
        "joint 3 correction +15.0000 deg exceeds the limit of 2 deg; if its motor was swapped "
        "or re-mastered, declare it with --swapped J3 (raises that joint's limit only); else "
        "check the cell and the data, and rerun with --force to push anyway")}
    outcome = derive_outcome([swap], SOURCES, run_dir="runs/x", finished=True)
    assert outcome.next_command == "hostpc calibrate --resume runs/x --swapped J3"
    small = {"event": "push_refused", "at": "t1", "reason": (
        "joint 1 correction +0.1682 deg exceeds the limit of 0.01 deg; check the cell "
        "and the data, and rerun with --force to push anyway")}
    outcome = derive_outcome([small], SOURCES, run_dir="runs/x", finished=True)
    assert outcome.next_command == "hostpc calibrate --resume runs/x --force"


def test_a_failed_model_check_without_a_push_sends_to_diagnose() -> None:
    check = {"event": "verify", "at": "t1", "verdict": "FAIL", "p_value": 4.8e-13,
             "offsets": [0.0] * 6}
    outcome = derive_outcome([check], SOURCES, run_dir="runs/x", finished=True)
    assert outcome.verdict == "NOT_PUSHED"
    assert outcome.next_command == "hostpc diagnose runs/x/dataset.json --ladder"
    assert "model check FAIL" in outcome.headline
    passed = {**check, "verdict": "PASS", "p_value": 0.4}
    outcome = derive_outcome([check, {"event": "resumed", "at": "t2"}, passed], SOURCES,
                             run_dir="runs/x", finished=True)
    assert outcome.next_command == "hostpc calibrate --resume runs/x --push"


def test_a_refusals_next_command_is_read_from_its_structured_fields_not_its_words() -> None:
    """The push_refused event carries which guard refused and the next command's words;
    the outcome reads those (a reworded reason changes nothing)."""
    from hostpc.calibrate.refusals import PushRefusal, resume_with

    declared = PushRefusal("joint 3 is 15 deg off (reworded)", "correction_limit",
                           resume_with("--swapped", "J3"), joint=3, limit_deg=2.0, declare=3)
    event = {"event": "push_refused", "at": "t1", **declared.to_event()}
    outcome = derive_outcome([event], SOURCES, run_dir="runs/x", finished=True)
    assert outcome.next_command == "hostpc calibrate --resume runs/x --swapped J3"
    assert outcome.refusal == declared
    # a moved reference refuses even with --force: its next command drops the reference
    moved = PushRefusal("the sphere frame moved 0.5 mm since the reference of 2026-11-28",
                        "reference_moved", resume_with("--reference", "none"))
    event = {"event": "push_refused", "at": "t1", **moved.to_event()}
    outcome = derive_outcome([event], SOURCES, run_dir="runs/x", finished=True)
    assert outcome.next_command == "hostpc calibrate --resume runs/x --reference none"
    limit = PushRefusal("the controller said no", "controller_limit", resume_with("--push"))
    event = {"event": "push_refused", "at": "t1", **limit.to_event(), "by": "controller"}
    outcome = derive_outcome([event], SOURCES, run_dir="runs/x", finished=True)
    assert outcome.next_command == "hostpc calibrate --resume runs/x --push"


def _restored(zeros: dict[str, str] | None) -> tuple[JointSource, ...]:
    """SOURCES with J1 and J6 resolved by a reference of run /runs/rec with `zeros` (its
    `joint_zeros`; None: a file written before it was kept)."""
    from hostpc.calibrate.outcome import restored_to_reference
    from hostpc.calibrate.reference import reference_from_dict

    document = {"format": "zerocal-cell-reference/1", "recorded": "2026-01-02T00:00:00",
                "robot": {"model": "ur5e"}, "method": "stereo_target",
                "source_run": "/runs/rec",
                "frames": {"target": {"parameters": ["x"], "nominal": [0.0], "delta": [0.0],
                                      "covariance": [[1e-8]]}},
                **({"joint_zeros": zeros} if zeros is not None else {})}
    reference = reference_from_dict(document, "test")
    coverage = {"resolved_by_reference": ["joint_offsets.q1", "joint_offsets.q6"]}
    return restored_to_reference(SOURCES, coverage, reference)


def test_a_joint_restored_to_a_reference_is_calibrated_only_if_its_run_measured_it() -> None:
    def headline(zeros: dict[str, str] | None) -> str:
        return derive_outcome([PUSH, VERIFY_PASS], _restored(zeros), run_dir="runs/x",
                              finished=True).headline

    measured = {str(j): "measured" for j in range(1, 7)}
    assert headline(measured) == "PASS: J1-J6 calibrated and verified"
    as_found = {**measured, "1": "as_found", "6": "as_found"}
    assert headline(as_found) == (
        "PASS: J2-J5 calibrated and verified; J1, J6 restored to the cell reference of "
        "/runs/rec (their zeros as at that run, not measured against a surveyed frame)")
    assert "J1, J6 restored to the cell reference of /runs/rec (whether that run " \
        "calibrated them is not recorded" in headline(None)
    # a rollback re-derives the outcome from the stored block: the record survives it
    from hostpc.calibrate.outcome import sources_from_outcome

    block = derive_outcome([PUSH, VERIFY_PASS], _restored(as_found), run_dir="runs/x",
                           finished=True).to_dict()
    again = derive_outcome([PUSH, VERIFY_PASS], sources_from_outcome(block),
                           run_dir="runs/x", finished=True)
    assert again.headline == headline(as_found)


def test_a_push_a_robot_keeps_no_offsets_for_is_applied_on_the_host_not_pushed() -> None:
    """A UR's push sets the driver's offsets on the host for the session only: the
    controller's zeros are unchanged, and the outcome says so (review item 6)."""
    from hostpc.robots.drivers import DRIVERS

    keep = DRIVERS["ur"].host_offsets
    outcome = derive_outcome([PUSH, VERIFY_PASS], SOURCES, run_dir="runs/x", finished=True,
                             host_offsets=keep)
    assert outcome.verdict == "PASS" and not outcome.pushed and outcome.applied_on_host
    assert outcome.controller.startswith(
        "zero offsets unchanged: the new ones are applied on the host for this session only "
        "(verified); to keep them: load runs/x/ur_calibration.yaml")
    assert "new offsets, verified" not in outcome.controller
    assert outcome.headline.startswith(
        "PASS: J1-J6 calibrated and verified; applied on the host for this session only: "
        "the controller's zero offsets are unchanged (to keep them: load "
        "runs/x/ur_calibration.yaml")
    assert all(not j.pushed and j.applied_on_host and j.verified for j in outcome.joints)
    block = outcome.to_dict()
    assert block["pushed"] is False and block["applied_on_host"] is True
    # a failed verification has nothing on the controller to roll back
    failed = derive_outcome([PUSH, {**VERIFY_PASS, "verdict": "FAIL"}], SOURCES,
                            run_dir="runs/x", finished=True, host_offsets=keep)
    assert failed.verdict == "FAIL" and "rollback" not in (failed.next_command or "")
    assert "the controller's zero offsets are unchanged" in failed.headline
    # the controller that keeps them: pushed, as before
    assert derive_outcome([PUSH, VERIFY_PASS], SOURCES, run_dir="runs/x",
                          finished=True).controller == "new offsets, verified"


def test_a_simulated_run_that_fails_verification_names_a_step_that_works() -> None:
    """`--robot sim`'s controller ends with the run: `hostpc rollback --run DIR` would exit 2
    ("nothing left to roll back"), so a failed verification there says so and names the
    diagnosis (review of the ninth stop, station item 10); a real controller's FAIL still
    names the rollback."""
    failed = derive_outcome([PUSH, {**VERIFY_PASS, "verdict": "FAIL"}], SOURCES,
                            run_dir="runs/x", finished=True, simulated=True)
    assert failed.verdict == "FAIL"
    assert failed.next_command == "hostpc diagnose runs/x/dataset.json --ladder"
    assert "nothing to roll back" in failed.headline
    real = derive_outcome([PUSH, {**VERIFY_PASS, "verdict": "FAIL"}], SOURCES,
                          run_dir="runs/x", finished=True)
    assert real.next_command == "hostpc rollback --run runs/x"
