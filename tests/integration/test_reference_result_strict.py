"""`hostpc reference record` reads the run's result.json strictly (hostpc.calibrate.
run_result.read_run_result, the strict reading FIT.json has): copies of a real run's folder
with a hand-edited result.json are refused in one line naming the file and the field (exit
2), never a traceback and never a "false" that passes the did-not-converge guard; the note
on a joint the run did not calibrate names the --run given, not the folder result.json
recorded."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from hostpc.cli.main import main

Edit = Callable[[str], str]


def _set(path: tuple[str, ...], value: Any) -> Edit:
    def edit(text: str) -> str:
        document = json.loads(text)
        block = document
        for key in path[:-1]:
            block = block[key]
        block[path[-1]] = value
        return json.dumps(document)
    return edit


EDITS: dict[str, tuple[Edit, str]] = {
    "verify list": (_set(("verify",), [1, 2]), "verify: expected an object, got list"),
    "converged string": (_set(("fit", "converged"), "false"),
                         "fit.converged: expected true or false (a JSON boolean, not a "
                         "string), got 'false'"),
    "effects string": (_set(("fit", "effects"), "joint_offsets"),
                       "fit.effects: expected a list"),
    "duplicate key": (lambda text: text.replace('"fit": {', '"fit": {}, "fit": {', 1),
                      "key 'fit' appears twice in one object"),
    "NaN": (lambda text: text[:-1].rstrip().rstrip("}") + ', "zz": NaN}',
            "NaN is not a number JSON allows"),
    "unknown zeros": (_set(("outcome", "unknown_zeros"), ["J6"]),
                      "outcome.unknown_zeros[0]: expected an integer"),
}


@pytest.fixture(scope="module")
def first_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = tmp_path_factory.mktemp("ref") / "first"
    assert main(["calibrate", "--robot", "sim", "--out", str(run), "--no-report"]) == 0
    return run


@pytest.mark.parametrize("name", list(EDITS))
def test_a_hand_edited_result_is_refused_in_one_line(
        first_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        name: str) -> None:
    edit, message = EDITS[name]
    copy = tmp_path / "copy"
    shutil.copytree(first_run, copy)
    result = copy / "result.json"
    result.write_text(edit(result.read_text()))
    capsys.readouterr()
    code = main(["reference", "record", "--run", str(copy), "--out", str(tmp_path / "r.json")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"{result}: {message}" in err, err
    assert not (tmp_path / "r.json").exists()


def test_the_note_names_the_run_given(first_run: Path, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(first_run, copy)
    capsys.readouterr()
    assert main(["reference", "record", "--run", str(copy), "--out",
                 str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert f"note: J6 was not calibrated by {copy} (" in out, out
    assert str(first_run) not in out.split("note:", 1)[1]
