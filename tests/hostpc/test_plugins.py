"""User effects from a Python file: loaded, fitted, and bad plugins refused in one line."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from hostpc.errors import EffectError
from hostpc.fitting import fit
from hostpc.model.registry import load_plugin_file, parse_effect_list
from hostpc.synthesize import random_truth, synthesize_stereo_target

WRIST_COUPLING = textwrap.dedent('''
    import numpy as np
    from hostpc.model.effect import Effect

    class WristCoupling(Effect):
        """Joint 5 turns with the cosine of joint 6: dq5 = k * cos(q6)."""
        name = "wrist_coupling"
        hook = "joint"
        unit = "rad"

        def parameter_names(self, ctx):
            return ["k"]

        def joint_delta(self, ctx, p):
            delta = np.zeros_like(ctx.q_cmd)
            delta[:, 4] = p[0] * np.cos(ctx.q_cmd[:, 5])
            return delta

        def joint_jacobian(self, ctx, p):
            return None  # let zerocal differentiate it numerically
''')


def test_plugin_effect_is_loaded_and_fitted(tmp_path: Path, stereo_poses) -> None:  # type: ignore[no-untyped-def]
    plugin = tmp_path / "wrist.py"
    plugin.write_text(WRIST_COUPLING)
    assert set(load_plugin_file(plugin)) == {"wrist_coupling"}
    truth = {k: v for k, v in random_truth(np.random.default_rng(3)).items()
             if k.startswith("joint_offsets")}
    base = synthesize_stereo_target(truth, q=stereo_poses, seed=3, known=("tool", "target"))
    # synthesise with the plugin's effect hidden, via the same model
    from dataclasses import replace

    from hostpc.model.measurements.predict import predict
    from hostpc.model.problem import build_problem

    problem = build_problem(base.dataset, ["joint_offsets", "wrist_coupling"], plugins=[plugin])
    x = np.array([truth.get(n, 0.0) for n in problem.layout.names])
    x[problem.layout.index("wrist_coupling.k")] = 1e-3
    clean, _ = predict(problem, x, jacobian=False)
    noise = base.dataset.samples.p - predict(build_problem(base.dataset), np.array(
        [truth[n] for n in build_problem(base.dataset).layout.names]), jacobian=False)[0]
    data = base.dataset.with_samples(replace(base.dataset.samples, p=clean + noise))
    lean = fit(data, cv_folds=0)
    full = fit(data, "+wrist_coupling", plugins=[plugin], cv_folds=0)
    assert lean.chi2_dof > 3.0
    assert full.chi2_dof < 1.5
    assert abs(full.value("wrist_coupling.k") - 1e-3) < 3 * full.sigma("wrist_coupling.k")


@pytest.mark.parametrize("source, message", [
    ("raise RuntimeError('boom')", "failed to import: RuntimeError: boom"),
    ("x = 1", "defines no Effect subclass"),
    ("from hostpc.model.effect import Effect\nclass A(Effect):\n    name = 'a'\n"
     "    hook = 'nowhere'\n", "has hook 'nowhere'"),
    ("def broken(:\n", "failed to import: SyntaxError"),
    ("raise SystemExit(0)", "failed to import: SystemExit: 0"),
])
def test_bad_plugins_raise_one_line(tmp_path: Path, source: str, message: str) -> None:
    plugin = tmp_path / "bad.py"
    plugin.write_text(source)
    with pytest.raises(EffectError) as info:
        load_plugin_file(plugin)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_missing_plugin_file(tmp_path: Path) -> None:
    with pytest.raises(EffectError, match="no such file"):
        load_plugin_file(tmp_path / "nope.py")


def test_effect_list_spec() -> None:
    default = ["joint_offsets", "tool", "target"]
    assert parse_effect_list(None, default) == default
    assert parse_effect_list("+backlash", default) == default + ["backlash"]
    assert parse_effect_list("+backlash,-tool", default) == ["joint_offsets", "target",
                                                             "backlash"]
    assert parse_effect_list("joint_offsets,geometry", default) == ["joint_offsets", "geometry"]


BROKEN_SIGN = textwrap.dedent('''
    import numpy as np
    from hostpc.model.effect import Effect

    class Wrong(Effect):
        name = "wrong"
        hook = "joint"

        def parameter_names(self, ctx):
            return ["k"]

        def joint_delta(self, ctx, p):
            delta = np.zeros_like(ctx.q_cmd)
            delta[:, 1] = p[0] * np.cos(ctx.q_cmd[:, 2])
            return delta

        def joint_jacobian(self, ctx, p):
            J = np.zeros(ctx.q_cmd.shape + (1,))
            J[:, 1, 0] = -np.cos(ctx.q_cmd[:, 2])   # wrong sign
            return J
''')


def test_plugin_with_a_wrong_jacobian_is_refused(tmp_path: Path) -> None:
    plugin = tmp_path / "wrong.py"
    plugin.write_text(BROKEN_SIGN)
    data = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo.json"
    from hostpc.dataset import load_dataset

    with pytest.raises(EffectError, match="disagrees with a numeric derivative"):
        fit(load_dataset(data), "+wrong", plugins=[plugin])


def test_plugin_not_zero_at_zero_is_refused(tmp_path: Path) -> None:
    plugin = tmp_path / "offset.py"
    plugin.write_text(BROKEN_SIGN.replace("p[0] * np.cos", "(p[0] + 1e-3) * np.cos"))
    data = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo.json"
    from hostpc.dataset import load_dataset

    with pytest.raises(EffectError, match="nominal model"):
        fit(load_dataset(data), "+wrong", plugins=[plugin])


def test_plugin_raising_system_exit_is_one_line_exit_2_in_the_cli(tmp_path: Path) -> None:
    """`raise SystemExit(0)` in a plugin used to end `hostpc fit` with exit 0, no output."""
    import subprocess
    import sys
    plugin = tmp_path / "evil.py"
    plugin.write_text("raise SystemExit(0)\n")
    dataset = Path(__file__).resolve().parents[2] / "examples" / "ur5e_stereo_known_frames.json"
    run = subprocess.run([sys.executable, "-m", "hostpc.cli.main", "fit", str(dataset),
                          "--plugin", str(plugin)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "evil.py" in run.stderr and "SystemExit" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1
