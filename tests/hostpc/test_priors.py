"""Priors and holds by name (hostpc.fitting.priors): parsing, a wrong prior moves the
parameter by the predicted amount, held parameters are bit-identical, a prior can make a
direction identifiable, the CLI answers bad names with one line and exit 2."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.dataset import dataset_to_dict
from hostpc.errors import InputError
from hostpc.fitting import fit
from hostpc.fitting.priors import parse_prior, with_constraints
from hostpc.synthesize import random_truth, synthesize_stereo_target

UNITS = {"tool.x": "m", "joint_offsets.q1": "rad", "effect.k": "rad/(N m)"}


def test_parse_units_as_printed() -> None:
    prior = parse_prior("tool.x=0.045+-0.0005m", UNITS)
    assert (prior.name, prior.value, prior.sigma) == ("tool.x", 0.045, 0.0005)
    prior = parse_prior("tool.x = 45 +- 0.5 mm", UNITS)
    assert prior.value == pytest.approx(0.045) and prior.sigma == pytest.approx(5e-4)
    prior = parse_prior("joint_offsets.q1=0.02+-0.01deg", UNITS)
    assert prior.value == pytest.approx(math.radians(0.02))
    assert prior.sigma == pytest.approx(math.radians(0.01))
    assert parse_prior("effect.k=1e-6+-2e-7", UNITS).sigma == 2e-7  # SI without a unit


@pytest.mark.parametrize("text, message", [
    ("tool.q=0+-1m", "unknown parameter"),
    ("tool.x=0+-1deg", "does not fit"),
    ("tool.x=0+-0m", "sigma positive"),
    ("tool.x=0+-1mm+", "expected NAME=VALUE"),
    ("tool.x 0.1", "expected NAME=VALUE"),
    ("tool.x=1e308+-1e-308m", "outside the physical range"),
    ("tool.x=1e3+-1m", "outside the physical range"),
    ("joint_offsets.q1=0+-1e-308deg", "sigma .* is outside"),
    ("tool.x=0+-1e300m", "sigma .* is outside"),
    ("effect.k=1e300+-1", "outside the physical range"),
])
def test_parse_errors_are_input_errors(text: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        parse_prior(text, UNITS)


@pytest.fixture(scope="module")
def exact_data(stereo_poses: np.ndarray):  # type: ignore[no-untyped-def]
    truth = {k: v for k, v in random_truth(np.random.default_rng(21)).items()
             if not k.startswith("target.")}
    return synthesize_stereo_target(truth, q=stereo_poses, noise_scale=0.0, known=("target",))


def test_wrong_prior_moves_the_parameter_by_the_predicted_amount(exact_data) -> None:  # type: ignore[no-untyped-def]
    truth = exact_data.truth
    name, shift, sigma = "tool.x", 5e-6, 2e-6
    prior = f"{name}={truth[name] + shift!r}+-{sigma!r}m"
    result = fit(exact_data.dataset, cv_folds=0, priors=[prior])
    assert result.converged
    # noise-free data: the fit moves by shift * posterior variance / prior variance
    # (Gauss-Newton with the prior as one more row; linear to first order)
    predicted = shift * result.std[result.names.index(name)] ** 2 / sigma**2
    moved = result.value(name) - truth[name]
    assert predicted > 0.1 * shift  # a prior strong enough to matter
    assert moved == pytest.approx(predicted, rel=0.02)


def test_held_parameters_are_bit_identical(exact_data) -> None:  # type: ignore[no-untyped-def]
    held = ("tool.z", "joint_offsets.q2")
    result = fit(exact_data.dataset, cv_folds=0, hold=list(held))
    free_fit = fit(exact_data.dataset, cv_folds=0)
    for name in held:
        assert result.value(name) == 0.0  # the start value, bit for bit
        assert result.fixed[result.names.index(name)]
        assert free_fit.value(name) != 0.0
    x0 = np.full(result.problem.layout.size, 1e-4)
    started = fit(exact_data.dataset, cv_folds=0, hold=list(held), x0=x0)
    for name in held:
        assert started.value(name) == 1e-4


def test_prior_makes_a_direction_identifiable(exact_data) -> None:  # type: ignore[no-untyped-def]
    plain = fit(exact_data.dataset, cv_folds=0)
    assert "joint_offsets.q6" in {d.fixed for d in plain.unidentifiable}
    truth = exact_data.truth
    prior = f"tool.rz={truth['tool.rz']!r}+-1e-6rad"
    result = fit(exact_data.dataset, cv_folds=0, priors=[prior])
    assert not result.unidentifiable
    assert "make 1 direction(s) identifiable" in result.message
    assert result.value("joint_offsets.q6") == pytest.approx(truth["joint_offsets.q6"],
                                                             abs=1e-8)


def test_dataset_file_priors_and_hold(exact_data, tmp_path: Path,  # type: ignore[no-untyped-def]
                                      capsys: pytest.CaptureFixture[str]) -> None:
    document = dataset_to_dict(exact_data.dataset)
    document["priors"] = {"tool.rz": {"value": math.degrees(exact_data.truth["tool.rz"]),
                                      "sigma": 1e-4, "unit": "deg"}}
    document["hold"] = ["tool.z"]
    path = tmp_path / "d.json"
    path.write_text(json.dumps(document))
    assert main(["fit", str(path), "--cv-folds", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["parameters"]["tool.z"]["value"] == 0.0
    assert not out["unidentifiable"]
    # the CLI adds to the file's
    assert main(["fit", str(path), "--cv-folds", "0", "--json", "--hold", "tool.y,tool.x",
                 "--prior", "joint_offsets.q1=0+-0.01deg"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["parameters"]["tool.x"]["value"] == out["parameters"]["tool.y"]["value"] == 0.0


@pytest.mark.parametrize("option", [["--prior", "tool.q=0+-1m"], ["--hold", "nope"],
                                    ["--prior", "tool.x=1+-2deg"], ["--prior", "garbage"],
                                    ["--prior", "tool.x=1e308+-1e-308m"],
                                    ["--hold", "joint_offsets.q1",
                                     "--prior", "joint_offsets.q1=0.5+-0.01deg"]])
def test_cli_bad_prior_or_hold_one_line_exit_2(exact_data, tmp_path: Path, option: list[str],  # type: ignore[no-untyped-def]
                                               capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "d.json"
    path.write_text(json.dumps(dataset_to_dict(exact_data.dataset)))
    for command in ("fit", "diagnose"):
        assert main([command, str(path), "--cv-folds", "0", *option]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1, err
        assert "Traceback" not in err
        if "--hold" in option and "--prior" in option:
            assert "joint_offsets.q1 is both held and given a prior" in err


def test_with_constraints_keeps_the_dataset_otherwise(exact_data) -> None:  # type: ignore[no-untyped-def]
    same = with_constraints(exact_data.dataset)
    assert same is exact_data.dataset
    changed = with_constraints(exact_data.dataset, ["tool.x=0+-1m"], "tool.y")
    assert changed.samples is exact_data.dataset.samples
    assert changed.extra_fields["hold"] == ["tool.y"]
