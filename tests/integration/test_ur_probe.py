"""End to end: `hostpc calibrate --driver ur --method sphere_probe` against the stub's UR
personality recovers the injected offsets as the zerocal protocol driver does.

Both runs use the same simulated world (`--robot sim --method sphere_probe`'s default: a
2 ms probe trigger latency, a surveyed sphere, motions without wall time) on a fresh
`controller-stub serve --ur` subprocess each, the same planning seed and the same cell file
(the sphere declared known). The protocol driver's guarded move is the simulated
controller's own latch; the UR run drives the robot with the real ur_rtde library: an
asynchronous moveJ that the stub moves cycle by cycle (2 ms) while the probe input follows
the stylus, watched sample by sample over RTDE and stopped with stopJ at the input edge
(docs/ur-probe.md). The UR latch is quantised by the 500 Hz RTDE samples, so its offsets are
about ten times less precise; both must land within 3 sigma of the truth (as the sphere_probe
CLI test asks), agree with each other, and fit the trigger latency.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("rtde_control")

from hostpc.robots.simulator import default_sim_scenario, sim_default_known  # noqa: E402
from tests.integration.ur_stub import TOKEN, ur_stub_process  # noqa: E402

TRUE_LATENCY_S = 0.002
"""The default world's probe trigger latency."""


def _calibrate(tmp_path: Path, driver: str) -> tuple[dict[str, Any], np.ndarray]:
    cell = tmp_path / "cell.json"
    cell.write_text(json.dumps({"known": list(sim_default_known("sphere_probe"))}))
    base = default_sim_scenario(0.0, "sphere_probe")
    with ur_stub_process(tmp_path / f"{driver}-stub", {"server": {"token": TOKEN}},
                         base=base) as stub:
        run = subprocess.run(
            [sys.executable, "-m", "hostpc.cli.main", "calibrate",
             "--robot", f"{stub.host}:{stub.port}", "--driver", driver, "--token", TOKEN,
             "--method", "sphere_probe", "--cell", str(cell), "--seed", "0",
             "--out", str(tmp_path / driver), "--json", "--no-report"],
            capture_output=True, text=True, timeout=900,
        )
        assert run.returncode == 0, run.stderr[-3000:]
        truth = json.loads(stub.truth_out.read_text())
        if driver == "ur":  # the stub moved the async moves cycle by cycle and logged contacts
            assert "probe contact: latched q" in stub.log.read_text()
    return json.loads(run.stdout), np.degrees(truth["zero_errors_initial"])


def _latency(document: dict[str, Any]) -> tuple[float, float]:
    fit = json.loads(Path(document["fit"]["file"]).read_text())
    found = _find(fit, "trigger_latency.latency")
    assert found is not None, "no fitted trigger latency"
    return float(found["value"]), float(found["std"])


def _find(tree: Any, key: str) -> Any:
    if isinstance(tree, dict):
        if key in tree:
            return tree[key]
        tree = list(tree.values())
    if isinstance(tree, list):
        for item in tree:
            found = _find(item, key)
            if found is not None:
                return found
    return None


@pytest.mark.slow
def test_ur_probe_recovers_the_offsets_like_the_protocol_driver(tmp_path: Path) -> None:
    reference, truth = _calibrate(tmp_path, "zerocal")
    document, truth_ur = _calibrate(tmp_path, "ur")
    np.testing.assert_allclose(truth_ur, truth)  # the same world
    assert document["robot"]["driver"] == "ur"
    for doc in (reference, document):
        assert "trigger_latency" in doc["fit"]["effects"]
        assert doc["fit"]["chi2_dof"] < 2.0
        assert doc["verify"]["passed"], doc["verify"]
        assert doc["push"]["status"] == ("applied_on_host" if doc is document else "pushed")

    rows, reference_rows = document["offsets"]["joints"], reference["offsets"]["joints"]
    for j in range(5):  # q1-q5 identifiable (surveyed sphere); q6: the tip is on its axis
        ur, ref = rows[j], reference_rows[j]
        assert abs(ref["correction_deg"] - truth[j]) <= 3 * ref["sigma_deg"], (j, ref)
        assert abs(ur["correction_deg"] - truth[j]) <= 3 * ur["sigma_deg"], (j, ur, truth[j])
        both = float(np.hypot(ur["sigma_deg"], ref["sigma_deg"]))
        assert abs(ur["correction_deg"] - ref["correction_deg"]) <= 3 * both, (j, ur, ref)
        # the RTDE latch is coarser, but not by more than ~20 times
        assert ur["sigma_deg"] < 20 * ref["sigma_deg"]
    assert rows[5]["correction_deg"] is None and reference_rows[5]["correction_deg"] is None

    # the latch timing the UR driver measured: the midpoint of the edge window is unbiased,
    # so the fitted latency is the probe's own
    latency, sigma = _latency(document)
    assert abs(latency - TRUE_LATENCY_S) <= max(3 * sigma, 2e-4), (latency, sigma)
