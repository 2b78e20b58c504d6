"""The summary's push and verification lines say what happened, in words that cannot be
misread (a PASS never reads like a FAIL, a replay never claims to have written a robot)."""

from __future__ import annotations

from typing import Any

from hostpc.calibrate.summary import _push_line, _verify_line


def _verify(p_value: float) -> dict[str, Any]:
    return {"n_planned": 10, "n_measured": 10, "p_value": p_value, "statistic": 7.83,
            "dof": 30, "alpha": 0.01, "tolerance_mm": None, "verdict": "PASS",
            "passed": True, "pushed": True, "rms_before_mm": 3.8, "max_before_mm": 4.7,
            "rms_after_mm": 0.015, "max_after_mm": 0.028}


def test_the_verify_line_states_the_fail_rule_and_never_rounds_p_to_1() -> None:
    line = _verify_line(_verify(0.99962))
    assert "p > 0.999 (FAIL if p < alpha = 0.01)" in line and line.endswith(": PASS")
    assert "FAIL below" not in line and "p = 1 " not in line
    assert "p = 0.997 (FAIL if p < alpha = 0.01)" in _verify_line(_verify(0.9971))


def test_a_replayed_push_says_nothing_was_written() -> None:
    document = {"push": {"status": "pushed", "rollback_id": "rb-1"}, "run_dir": "rep",
                "robot": {"address": "replay:rec", "driver": "replay", "sim": False}}
    line = _push_line(document)
    assert "replayed from the recording" in line and "nothing written to a robot" in line
    assert "rollback" not in line
    document["robot"] = {"address": "10.0.0.2:30010", "driver": "zerocal", "sim": False}
    assert "undo with hostpc rollback --run rep" in _push_line(document)
