"""sphere_probe through the shared calibration runner (journal, plan, fit, push, verify)
against the real controller stub on 127.0.0.1."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hostpc.methods.base import RunSettings
from tests.integration.conftest import StartStub
from tests.integration.runner_runs import run_on


@pytest.mark.slow
async def test_runner_calibrates_pushes_verifies_and_resumes(start_stub: StartStub,
                                                             tmp_path: Path) -> None:
    server = await start_stub({"truth": {"probe_trigger_latency_s": 0.0}})
    truth_before = np.asarray(server.sim.truth()["zero_errors"], float)
    settings = RunSettings(method="sphere_probe", n_poses=100, n_verify=10, seed=3,
                           cv_folds=0)
    run_dir = tmp_path / "run"
    outcome = await run_on(server, run_dir, settings)
    assert outcome.fit is not None and outcome.dataset is not None
    assert outcome.dataset.method == "sphere_probe" and outcome.dataset.n_samples == 100
    assert (run_dir / "probe_plan.json").is_file()
    fixed = {d.fixed for d in outcome.fit.unidentifiable}
    assert fixed == {"joint_offsets.q1", "joint_offsets.q6"}
    # the push wrote the identifiable corrections only: the stub's remaining zero errors
    # on joints 2-5 are at the fit's noise level, joints 1 and 6 untouched
    after = np.asarray(server.sim.truth()["zero_errors"], float)
    assert np.all(np.abs(after[1:5]) < 1e-4)
    assert after[0] == pytest.approx(truth_before[0]) and after[5] == pytest.approx(
        truth_before[5])
    assert outcome.verify is not None and outcome.verify.passed, outcome.verify
    assert outcome.exit_code == 0
    result = json.loads((run_dir / "result.json").read_text())
    assert result["method"] == "sphere_probe" if "method" in result else True

    # resume of the finished run: the stored result, nothing measured or written again
    journal = (run_dir / "journal.jsonl").read_text().splitlines()
    again = await run_on(server, run_dir)
    assert again.document == json.loads((run_dir / "result.json").read_text())
    assert again.exit_code == 0 and again.document["verify"]["verdict"] == "PASS"
    assert (run_dir / "journal.jsonl").read_text().splitlines() == journal
