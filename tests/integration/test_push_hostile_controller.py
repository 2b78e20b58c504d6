"""Push and rollback against controllers that misreport the write (tests/integration/
hostile_controller.py: real sockets on 127.0.0.1 port 0).

A push keeps the offsets it read before the write, never the controller's claim; it reads
the offsets back and a controller that holds other ones than asked (clamped, ignored) or
names other previous ones fails the push with one line (exit 4) naming the joints, both
values, what it holds and the next command; a push or a rollback cut short names the next
commands, which work; a hand-edited push.json is refused before anything is written; a
reply to a request never sent is one message; a calibration whose push the controller
clamps is never PASS, its resume says so again, its rollback restores the offsets read.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from hostpc.fitting import fit
from hostpc.robots.simulator import SimulatedController
from hostpc.synthesize import random_truth, synthesize_stereo_target
from tests.integration.hostile_controller import CLAMP_RAD, ClampingProxy, HostileController
from tests.integration.test_calibrate_sim import run_cli, sim_scenario, truth_rig_file

ZERO = [0.0] * 6


@pytest.fixture(scope="module")
def fit_text(stereo_poses: np.ndarray) -> str:
    """A noise-free offline fit of a ur5e (q1 and q6 held: unidentifiable)."""
    truth = random_truth(np.random.default_rng(5))
    data = synthesize_stereo_target(truth, q=stereo_poses, noise_scale=0.0)
    return json.dumps(fit(data.dataset, cv_folds=0).to_dict())


@pytest.fixture
def fit_file(tmp_path: Path, fit_text: str) -> Path:
    """The fit in a folder of its own (its push ledger is written beside it)."""
    path = tmp_path / "fit" / "fit.json"
    path.parent.mkdir()
    path.write_text(fit_text)
    return path


def _line(stderr: str) -> str:
    """The one line a failed command prints."""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    return lines[0]


def _next_command(line: str, words: str) -> list[str]:
    """The arguments of the command the line names after `words` (`with: hostpc ...`)."""
    found = re.search(re.escape(words) + r" with: hostpc ((?:rollback|status) --\S+ [^\s;()]+)",
                      line)
    assert found, line
    return found.group(1).split()


def _deg(value: float) -> str:
    return f"{math.degrees(value):+.5f}"


def test_push_keeps_the_offsets_it_read_and_rollback_restores_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], fit_file: Path) -> None:
    """The controller names 0.5 rad as the offsets it replaced (it read 0 before) and has
    forgotten the rollback id: the push fails (exit 4) saying its report is inconsistent,
    and the rollback writes the offsets read, not 0.5 rad (28.6 deg) on every joint."""
    out = tmp_path / "push"
    with HostileController("lie_prev") as controller:
        code, _, stderr = run_cli(capsys, "push", str(fit_file), "--robot",
                                  controller.address, "--out", str(out))
        assert code == 4, stderr
        line = _line(stderr)
        assert "report is inconsistent" in line, line
        assert "J1 +28.64789 deg (read before the write: +0.00000)" in line, line
        pushed = list(controller.offsets)
        assert pushed != ZERO
        record = json.loads((out / "push.json").read_text())
        assert record["previous_offsets"] == ZERO and record["new_offsets"] == pushed
        assert record["reported_previous_offsets"] == [0.5] * 6
        events = [json.loads(text) for text in (out / "journal.jsonl").read_text().splitlines()]
        assert [e["event"] for e in events] == ["push_intent", "push_written", "push"]
        assert events[-1]["previous_offsets"] == ZERO
        code, stdout, stderr = run_cli(capsys, *_next_command(line, "restore them"))
        assert code == 0, stderr
        assert controller.offsets == ZERO
        assert "J1 +0.00000" in stdout and "+28.6" not in stdout


@pytest.mark.parametrize("mode", ["clamp", "ignore"])
def test_push_reads_back_what_the_controller_holds(
        mode: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], fit_file: Path) -> None:
    """The controller says it stored the offsets but holds others (clamped to 0.001 rad,
    or its previous ones): one line naming the joints with both values, what it holds and
    the next command, exit 4; push.json keeps what it holds, the ledger too (the guard
    against pushing the fit twice compares with them); the next command works."""
    out = tmp_path / "push"
    with HostileController(mode) as controller:
        code, _, stderr = run_cli(capsys, "push", str(fit_file), "--robot",
                                  controller.address, "--out", str(out))
        assert code == 4, stderr
        line = _line(stderr)
        held = list(controller.offsets)
        record = json.loads((out / "push.json").read_text())
        new = record["new_offsets"]
        assert record["status"] == "pushed" and record["held_offsets"] == held
        assert record["previous_offsets"] == ZERO
        assert abs(new[1]) > CLAMP_RAD  # J2's correction is beyond the clamp
        assert f"J2 {_deg(held[1])} deg (pushed {_deg(new[1])})" in line, line
        assert "J1 " not in line.split("it holds now")[0]  # J1 was not pushed: not named
        assert "it holds now [deg]: J1 +0.00000, J2 " + _deg(held[1]) in line, line
        # the same fit again: the ledger knows the clamped offsets as this fit's
        code, _, stderr = run_cli(capsys, "push", str(fit_file), "--robot",
                                  controller.address, "--out", str(tmp_path / "again"))
        if mode == "clamp":
            assert code == 5 and "already carries this fit" in _line(stderr)
            command = _next_command(line, "restore them")
            assert command == ["rollback", "--run", str(out)]
        else:  # nothing changed: the fit may be pushed again (and fails again)
            assert code == 4 and "did not store" in _line(stderr)
            command = _next_command(line, "see what it holds")
            assert command == ["status", "--robot", controller.address]
        code, _, stderr = run_cli(capsys, *command)
        assert code == 0, stderr
        assert controller.offsets == ZERO


def test_a_rollback_the_controller_does_not_take_says_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], fit_file: Path) -> None:
    """Offsets of 0.01 rad before the push, a controller that clamps every write to 0.001
    rad and whose rollback undoes nothing: the rollback writes the offsets read before the
    push, the controller clamps them too, and the rollback says so (exit 4, one line)."""
    out = tmp_path / "push"
    with HostileController("clamp", offsets=[0.01] * 6) as controller:
        code, _, stderr = run_cli(capsys, "push", str(fit_file), "--robot",
                                  controller.address, "--out", str(out))
        assert code == 4 and "did not store" in _line(stderr), stderr
        code, stdout, stderr = run_cli(capsys, *_next_command(_line(stderr), "restore them"))
        assert code == 4, stderr
        assert "still does not hold the offsets read before the push" in _line(stderr)
        assert f"hostpc status --robot {controller.address}" in stderr
        assert controller.offsets == [CLAMP_RAD] * 6
        assert "J1 +0.05730" in stdout  # what it holds, in degrees


@pytest.mark.parametrize("mode, exit_code", [("slow_set", 4), ("drop_set_once", 3)])
def test_a_push_cut_short_names_the_next_commands_and_they_work(
        mode: str, exit_code: int, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        fit_file: Path) -> None:
    """No reply to set_offsets (exit 4), or the link closed after the controller stored
    them (exit 3): the line names `hostpc status --robot` and `hostpc rollback --run`,
    and both work: the controller ends with the offsets read before the push."""
    out = tmp_path / "push"
    with HostileController(mode) as controller:
        code, _, stderr = run_cli(capsys, "push", str(fit_file), "--robot",
                                  controller.address, "--out", str(out), "--timeout", "1")
        assert code == exit_code, stderr
        line = _line(stderr)
        assert "cut short" in line, line
        assert json.loads((out / "push.json").read_text())["status"] == "intent"
        status = _next_command(line, "see which")
        assert status == ["status", "--robot", controller.address]
        code, _, stderr = run_cli(capsys, *status)
        assert code == 0, stderr
        rollback = _next_command(line, "restore the previous ones either way")
        assert rollback == ["rollback", "--run", str(out)]
        code, stdout, stderr = run_cli(capsys, *rollback)
        assert code == 0, stderr
        assert controller.offsets == ZERO
        assert ("nothing to roll back" if mode == "slow_set" else "rolled back") in stdout


def test_a_read_back_lost_after_a_good_write_keeps_the_rollback_id(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], fit_file: Path) -> None:
    """The controller answers the write (rollback id rb-1) but stores the offsets clamped
    and never answers the read-back (exit 4): push.json and the journal keep the id, the
    line names it and `hostpc rollback --run DIR`, which undoes the write by that id (the
    controller holds neither the new nor the previous offsets, so without the id nothing
    could tell what to restore)."""
    out = tmp_path / "push"
    with HostileController("clamp_no_readback") as controller:
        code, _, stderr = run_cli(capsys, "push", str(fit_file), "--robot",
                                  controller.address, "--out", str(out), "--timeout", "1")
        assert code == 4, stderr
        line = _line(stderr)
        assert "took the write (rollback id rb-1)" in line, line
        assert controller.offsets != ZERO  # clamped: neither previous nor new
        record = json.loads((out / "push.json").read_text())
        assert record["rollback_id"] == "rb-1" and record["previous_offsets"] == ZERO
        events = [json.loads(text) for text in (out / "journal.jsonl").read_text().splitlines()]
        assert [e["event"] for e in events] == ["push_intent", "push_written"]
        assert events[-1]["rollback_id"] == "rb-1"
        rollback = _next_command(line, "restore the previous ones")
        assert rollback == ["rollback", "--run", str(out)]
        code, stdout, stderr = run_cli(capsys, *rollback)
        assert code == 0 and not stderr, stderr  # no "another host pushed later?"
        assert "rolled back rb-1" in stdout
        assert controller.offsets == ZERO


def _edited(text: str, **fields: object) -> str:
    document = json.loads(text)
    document.update(fields)
    if "rollback_id" in fields and fields["rollback_id"] is None:
        del document["rollback_id"]
    return json.dumps(document)


EDITS = {
    # the review's rb_big: an intent without rollback id, 3 rad (171.9 deg) before
    "other previous offsets": (lambda t: _edited(t, status="intent", rollback_id=None,
                                                 previous_offsets=[3.0] * 6,
                                                 pushed=[True] * 6),
                               "previous_offsets [+171.88734"),
    "a joint not pushed that changed": (lambda t: _edited(t, previous_offsets=[3.0] * 6),
                                        "joint J1 is not pushed"),
    "a string": (lambda t: _edited(t, previous_offsets="abc"),
                 "previous_offsets: expected a list, got 'abc'"),
    "five offsets": (lambda t: _edited(t, previous_offsets=ZERO[:5]),
                     "previous_offsets has 5"),
    "beyond half a turn": (lambda t: _edited(t, previous_offsets=[4.0] + ZERO[1:]),
                           "previous_offsets[0]:"),
    "a NaN": (lambda t: _edited(t).replace('"previous_offsets": [0.0', '"previous_offsets": [NaN'),
              "NaN is not a number JSON allows"),
    "a duplicated key": (lambda t: _edited(t).replace('"previous_offsets":',
                                             '"previous_offsets": [3, 3, 3, 3, 3, 3], '
                                             '"previous_offsets":', 1),
                         "'previous_offsets' appears twice"),
    "no rollback id": (lambda t: _edited(t, rollback_id=None), "rollback_id: required"),
}


def test_rollback_refuses_a_hand_edited_push_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], fit_file: Path) -> None:
    """push.json is validated like FIT.json before a rollback writes from it: each edit is
    one line, exit 2, and the controller keeps the pushed offsets."""
    out = tmp_path / "push"
    with HostileController("ok") as controller:
        code, _, stderr = run_cli(capsys, "push", str(fit_file), "--robot",
                                  controller.address, "--out", str(out))
        assert code == 0, stderr
        pushed = list(controller.offsets)
        original = (out / "push.json").read_text()
        for name, (edit, expected) in EDITS.items():
            edited = edit(original)
            assert edited != _edited(original), name
            (out / "push.json").write_text(edited)
            code, _, stderr = run_cli(capsys, "rollback", "--run", str(out))
            assert code == 2, (name, stderr)
            assert expected in _line(stderr), (name, stderr)
            assert controller.offsets == pushed, name
        # a push record of another robot (5 joints), in a folder without a journal
        alone = tmp_path / "alone"
        alone.mkdir()
        (alone / "push.json").write_text(_edited(
            original, previous_offsets=ZERO[:5], new_offsets=[0.001] * 5, pushed=[True] * 5))
        code, _, stderr = run_cli(capsys, "rollback", "--run", str(alone))
        assert code == 2, stderr
        assert f"5 offsets, the controller at {controller.address} has 6 joints" in \
            _line(stderr)
        assert controller.offsets == pushed
        (out / "push.json").write_text(original)  # the file as written: the rollback works
        code, _, stderr = run_cli(capsys, "rollback", "--run", str(out))
        assert code == 0, stderr
        assert controller.offsets == ZERO


def test_a_reply_to_a_request_never_sent_is_one_message(
        capsys: pytest.CaptureFixture[str]) -> None:
    """A reply whose reply_to names no request in flight fails the waiting request at
    once with that reason (before: a warning, then a timeout that named no reason)."""
    with HostileController("wrongid") as controller:
        code, _, stderr = run_cli(capsys, "status", "--robot", controller.address,
                                  "--timeout", "3")
    assert code == 4, stderr
    line = _line(stderr)
    assert "which is not pending" in line and "no reply" not in line, line


@pytest.mark.slow
def test_a_calibration_whose_push_the_controller_clamps_is_not_pass(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`hostpc calibrate` through a proxy that clamps the offsets written to the stub:
    the run stops at the push (exit 4, one line: what the controller holds, the rollback
    command), writes no result (no verdict, never PASS), its resume says the same, and the
    rollback restores the offsets read before the push."""
    scenario = sim_scenario()
    rig = truth_rig_file(scenario, tmp_path / "rig.json")
    out = tmp_path / "run"
    with SimulatedController(scenario, tmp_path / "stub") as sim, \
            ClampingProxy((sim.address.host, sim.address.port)) as proxy:
        before = list(sim.truth()["zero_offsets"])
        code, stdout, stderr = run_cli(
            capsys, "calibrate", "--robot", proxy.address, "--rig",
            str(rig), "--known", "target", "--poses", "16", "--verify-poses", "3",
            "--no-report", "--out", str(out))
        assert code == 4, stderr
        assert proxy.clamped == 1
        errors = [t for t in stderr.splitlines() if t.startswith("hostpc calibrate: error:")]
        assert len(errors) == 1, stderr  # the progress lines above it say what was done
        line = errors[0]
        assert "push failed" in line and "did not store" in line, line
        assert f"hostpc rollback --run {out}" in line, line
        assert not (out / "result.json").exists() and "PASS" not in stdout
        record = json.loads((out / "push.json").read_text())
        held = list(sim.truth()["zero_offsets"])
        assert record["previous_offsets"] == before and record["held_offsets"] == held
        assert held != record["new_offsets"]
        code, _, stderr = run_cli(capsys, "calibrate", "--resume", str(out))
        assert code == 4 and "did not store" in stderr, stderr
        code, _, stderr = run_cli(capsys, *_next_command(line, "restore them"))
        assert code == 0, stderr
        assert sim.truth()["zero_offsets"] == before


def test_a_calibration_whose_read_back_is_lost_keeps_the_id_and_its_resume_settles_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`hostpc calibrate` through a proxy that swallows the push's read-back (the write
    reached the stub and was answered, rb-1): the run stops (exit 4) with one line naming
    the id, the resume and the rollback; the resume finds the new offsets, records the push
    with that id and verifies it; the rollback then undoes the write by the id."""
    scenario = sim_scenario()
    rig = truth_rig_file(scenario, tmp_path / "rig.json")
    out = tmp_path / "run"
    with SimulatedController(scenario, tmp_path / "stub") as sim, \
            ClampingProxy((sim.address.host, sim.address.port), drop_read_back=True) as proxy:
        before = list(sim.truth()["zero_offsets"])
        code, _, stderr = run_cli(
            capsys, "calibrate", "--robot", proxy.address, "--rig", str(rig), "--known",
            "target", "--poses", "16", "--verify-poses", "3", "--no-report", "--timeout",
            "1", "--out", str(out))
        assert code == 4 and proxy.dropped == 1, stderr
        errors = [t for t in stderr.splitlines() if t.startswith("hostpc calibrate: error:")]
        assert len(errors) == 1, stderr
        line = errors[0]
        assert "took the write (rollback id rb-1) but reading its offsets back failed" in line
        assert f"settle and verify it with: hostpc calibrate --resume {out}" in line, line
        assert f"restore the previous ones with: hostpc rollback --run {out}" in line, line
        assert json.loads((out / "push.json").read_text())["rollback_id"] == "rb-1"
        pushed = list(sim.truth()["zero_offsets"])
        assert pushed != before
        code, stdout, stderr = run_cli(capsys, "calibrate", "--resume", str(out), "--json")
        assert code == 0, stderr
        assert "recorded as pushed, rollback id rb-1" in stderr
        record = json.loads((out / "push.json").read_text())
        assert (record["status"], record["rollback_id"]) == ("pushed", "rb-1")
        assert json.loads(stdout)["outcome"]["verdict"] == "PASS"
        code, stdout, stderr = run_cli(capsys, "rollback", "--run", str(out))
        assert code == 0, stderr
        assert "rolled back rb-1" in stdout and sim.truth()["zero_offsets"] == before
