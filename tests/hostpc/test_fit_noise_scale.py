"""A fit does not depend on a uniform stated sigma (docs/fitting.md, "Weak directions"): the
weak-parameter rule judges the sigmas at the measured noise. And what the fit counts and
prints about the noise: masked axes are no degrees of freedom; a chi2/dof below its band
(the stated noise pessimistic) shows the sigmas at the measured noise beside the stated.
Real data: FIGAROH's TALOS set (tests/data/README.md)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import hostpc
from hostpc.cli.main import main
from tests.hostpc.realdata import DATA, import_csv

CSV = DATA / "figaroh_talos_left_arm_mocap.csv"
TALOS = ["--method", "world_point", "--robot", str(DATA / "talos_left_arm.urdf"),
         "--base-link", "base_link", "--tip-link", "arm_left_7_link",
         "--columns", "q=torso_1_joint:arm_left_7_joint,x=x1,y=y1,z=z1,t=t"]


@pytest.fixture(scope="module")
def imports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("talos_sigma")
    return {sigma: import_csv(CSV, folder / f"talos_{sigma}.json", *TALOS, "--sigma", sigma)
            for sigma in ("0.001", "0.00036")}


def test_a_uniform_stated_sigma_changes_neither_what_is_held_nor_the_values(
        imports: dict[str, Path]) -> None:
    pessimistic, honest = (hostpc.fit(hostpc.load_dataset(imports[s]), "+geometry", cv_folds=0)
                           for s in ("0.001", "0.00036"))
    assert pessimistic.converged and honest.converged
    assert pessimistic.fixed.tolist() == honest.fixed.tolist()
    assert pessimistic.dof == honest.dof
    np.testing.assert_allclose(pessimistic.x, honest.x, atol=1e-7)
    # the stated sigmas scale with the stated noise; the measured-noise ones do not
    free = ~pessimistic.fixed
    np.testing.assert_allclose(pessimistic.std[free] / honest.std[free], 0.001 / 0.00036,
                               rtol=1e-6)
    assert pessimistic.chi2_dof * (0.001 / 0.00036) ** 2 == pytest.approx(honest.chi2_dof,
                                                                           rel=1e-6)


def test_masked_axes_are_no_degrees_of_freedom(imports: dict[str, Path]) -> None:
    dataset = hostpc.load_dataset(imports["0.001"])
    mask = np.ones((len(dataset.samples.q), 3))
    mask[[3, 17, 33, 50], 2] = 0.0  # four samples lost their z
    samples = dataclasses.replace(dataset.samples,
                                  fields={**dataset.samples.fields, "mask": mask})
    masked = hostpc.fit(dataclasses.replace(dataset, samples=samples), cv_folds=0)
    whole = hostpc.fit(dataset, cv_folds=0)
    assert masked.fixed.tolist() == whole.fixed.tolist()
    assert masked.dof == whole.dof - 4


def test_a_chi2_below_its_band_shows_the_sigmas_at_the_measured_noise(
        imports: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["fit", str(imports["0.001"])]) == 0
    out = capsys.readouterr().out
    assert "x sqrt(chi2/dof)" in out
    assert "chi2/dof is below its band" in out and "the stated noise is pessimistic" in out


def test_small_sigmas_print_with_significant_digits(imports: dict[str, Path]) -> None:
    from hostpc.cli.format import format_parameter_table

    result = hostpc.fit(hostpc.load_dataset(imports["0.00036"]), cv_folds=0)
    # sigmas 1e-4 of these (a stiff rig's, ~5e-5 deg): each printed, none as 0.0000
    tiny = dataclasses.replace(result, std=result.std * 1e-4)
    rows = [line.split() for line in format_parameter_table(tiny)[1:]]
    free = [row for row in rows if "(fixed)" not in row]
    assert free and all(float(row[2]) > 0.0 for row in free), rows
    q4 = next(row for row in free if row[0] == "joint_offsets.q4")
    assert float(q4[2]) == pytest.approx(np.degrees(tiny.sigma("joint_offsets.q4")), rel=5e-3)
