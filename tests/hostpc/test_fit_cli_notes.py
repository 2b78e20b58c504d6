"""What `hostpc fit` and `hostpc import` say in four corners (issue 25, review R2):
`--effects auto` prints diagnose's outlier note (the same sentence, from the same function);
a fit with no degrees of freedom never says a plain "converged"; a dataset of a plugin kind
read without `--plugin` names the kind and the option; a CSV row cut short names its row and
the columns it lacks (a multi-reflector row was read as "reflector not seen")."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hostpc.cli.main import main
from hostpc.dataset import save_dataset
from hostpc.diagnostics import diagnose
from hostpc.diagnostics.advice import outlier_note
from tests.hostpc.diagnose_support import hidden_dataset, hidden_world_point
from tests.hostpc.test_diagnose_robust import eight_sigma


def test_auto_prints_the_outlier_note_of_diagnose(tmp_path: Path, capsys) -> None:
    glitch = eight_sigma(hidden_dataset({}, seed=3).dataset, 17)
    save_dataset(glitch, tmp_path / "glitch.json")
    note = outlier_note(diagnose(glitch, cv_folds=0, rank_cv_folds=0).check)
    assert note.startswith("Sample #17")
    assert main(["fit", str(tmp_path / "glitch.json"), "--effects", "auto"]) == 0
    out = capsys.readouterr().out
    assert f"outliers: {note}" in out
    assert main(["fit", str(tmp_path / "glitch.json"), "--effects", "auto", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["model_choice"]["outliers"] == note


def test_a_fit_without_degrees_of_freedom_does_not_say_converged(tmp_path: Path,
                                                                  capsys) -> None:
    dataset = hidden_world_point({}, seed=4, n_samples=60).dataset
    six = dataset.with_samples(dataset.samples.subset(np.arange(6)))  # 18 numbers, 18 free
    save_dataset(six, tmp_path / "six.json")
    assert main(["fit", str(tmp_path / "six.json")]) == 0
    line = capsys.readouterr().out.splitlines()[1]
    assert "converged: yes" not in line
    assert "0 degrees of freedom" in line and "nothing tests the model" in line
    # how many more, said here (diagnose answers "adequate" at 0 dof, with no count)
    assert "at least 1 more sample for one degree of freedom (3 numbers each)" in line
    assert "hostpc diagnose" not in line


def test_a_plugin_kind_without_plugin_names_the_option(tmp_path: Path, capsys) -> None:
    from tests.integration.test_example_kind import synthetic_file

    path = synthetic_file(tmp_path)
    for command in ("fit", "diagnose"):
        assert main([command, str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "'tracker_range'" in err[0] and "--plugin FOLDER" in err[0]


@pytest.mark.parametrize(("columns", "row", "missing"), [
    ("q=q1:q6,x=x,y=y,z=z", "0.1,0.2,0.3,0.4,0.5,0.6,1.0,2.0", "no cell for z"),
    ("q=q1:q6,marker.a=x:z,marker.b=x2:z2", "0.1,0.2,0.3,0.4,0.5,0.6,1.0,2.0,3.0,4.0",
     "no cell for y2, z2"),
])
def test_a_row_cut_short_is_one_line_with_its_row(tmp_path: Path, capsys, columns, row,
                                                   missing) -> None:
    header = "q1,q2,q3,q4,q5,q6,x,y,z" + (",x2,y2,z2" if "x2" in columns else "")
    full = "0.1,0.2,0.3,0.4,0.5,0.6,1.0,2.0,3.0" + (",4.0,5.0,6.0" if "x2" in columns else "")
    (tmp_path / "t.csv").write_text("\n".join([header, full, full, row, full]) + "\n")
    assert main(["import", str(tmp_path / "t.csv"), "--method", "world_point", "--robot",
                 "ur5e", "--columns", columns, "--no-guess", "-o",
                 str(tmp_path / "t.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "row 4:" in err[0] and missing in err[0], err
    assert not (tmp_path / "t.json").exists()
