"""Issue 29, item 6: the default short run's report agrees with its verdict. The default
`hostpc calibrate --robot sim` (9-11 poses, 4 fresh) PASSes; its report used to advise "too
few samples to judge reliably ... measure at least 36" and draw an empty candidate chart.
Now the advice says the calibration had enough, what a diagnosis needs with the exact
commands, and the chart is one sentence. The summary names the report's path.
And `hostpc status` against a camera service says it is one."""

from __future__ import annotations

import html
import json
import re
import shlex
from pathlib import Path

import pytest

from hostpc.cli.status import format_state, state_as_dict
from hostpc.sensors.camera_service import CameraService
from hostpc.sensors.stereo_camera import StereoCamera
from hostpc.transport import ControllerClient
from tests.hostpc.test_sensors import noise_images, write_sequence
from tests.integration.test_calibrate_sim import run_cli


def test_the_default_runs_report_sizes_its_advice_to_a_calibration(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "first"
    code, stdout, stderr = run_cli(capsys, "calibrate", "--robot", "sim", "--out", str(run))
    assert code == 0, stderr
    assert stdout.startswith("PASS")
    assert f"report: {run / 'report.html'}" in stdout.splitlines()  # the summary names it
    assert f"report: {run / 'report.html'}" in (run / "summary.txt").read_text()
    page = (run / "report.html").read_text(encoding="utf-8")
    advice = page[page.index("<h2>Advice</h2>"):page.index("<h2>Is the model adequate?")]
    assert "Too few samples to judge" not in advice  # the run verified: not "too few"
    plan = json.loads((run / "result.json").read_text())["plan"]
    n_fit = plan["n_poses"]
    assert f"Enough samples for a calibration: {n_fit} samples" in advice
    assert plan["n_verify"] == 3 and "verified on 3 fresh poses" in advice
    # what a diagnosis would need, as commands (code, never literal backticks)
    commands = [html.unescape(c) for c in re.findall(r"<code>(.*?)</code>", advice)]
    measure = next(c for c in commands if c.startswith("hostpc calibrate"))
    words = shlex.split(measure)
    found = re.search(r"A diagnosis needs at least (\d+) samples", advice)
    assert found is not None
    needed = int(found.group(1))
    assert needed > n_fit and words[words.index("--poses") + 1] == str(needed)
    assert "--no-push" in words and words[words.index("--robot") + 1] == "sim"
    assert Path(words[words.index("--scenario") + 1]) == run / "sim" / "scenario.json"
    out = words[words.index("--out") + 1]
    assert f"hostpc diagnose {out}/dataset.json --ladder" in commands
    assert "`" not in advice
    # where no candidate changes the fit: one sentence, not an empty chart frame; a chart
    # only with a bar to draw (the 9-pose default plan: depth_scale, delta BIC -1.4, not
    # significant)
    missing = page[page.index("Which effect is missing?"):page.index("Effect-agnostic")]
    if "No candidate effect changes the fit" in missing:
        assert "candidate effects by delta BIC" not in missing and "<svg" not in missing
    else:
        assert "<svg" in missing and re.search(r"<td>-\d+\.\d+</td>", missing)


async def test_status_against_a_camera_service_says_it_is_one(tmp_path: Path) -> None:
    """It printed 'controller ...: robot , mode idle ...' and an empty joint table."""
    camera = StereoCamera(write_sequence(tmp_path, "left", noise_images(1, 31)),
                          write_sequence(tmp_path, "right", noise_images(1, 32)))
    server = await CameraService(camera, "status-token").start("127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        client = await ControllerClient.connect("127.0.0.1", port, token="status-token")
        try:
            state = await client.state()
        finally:
            await client.close()
    finally:
        server.close()
        await server.wait_closed()
        camera.close()
    text = format_state(state, f"127.0.0.1:{port}")
    assert text.startswith(f"camera service 127.0.0.1:{port}")
    assert "no robot" in text and "stereo camera" in text
    assert "robot ," not in text and "joint" not in text.split("\n")[0].split(":")[0]
    assert "q [deg]" not in text  # no empty joint table
    assert state_as_dict(state, "x")["kind"] == "camera_service"
