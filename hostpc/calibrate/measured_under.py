"""The controller's zero offsets a run folder's dataset was measured under.

A fit's joint offsets are corrections to the offsets the robot was measured under: pushed
onto other offsets (e.g. the ones the run's own push already wrote) they add up twice. The
dataset format (shared/spec/dataset-format.md) has no field for them, but a dataset that
lies in a run folder has them beside it:

- `dataset.json`: the fit poses, measured under the offsets the run read from the
  controller at its start (run.json `initial.zero_offsets`, ``RunHeader.initial``);
- `verify_dataset.json`: the last verification round's poses, measured under the offsets
  its `verify_start` event names.

`hostpc fit DATASET --json` and a run's own fit.json record them in FIT.json
(``measured_under``: the run folder, the dataset's name, the offsets, rad), and `hostpc
push` compares them with what the controller holds (hostpc/cli/push.py). Any other dataset
(another name, no run.json beside it, a run header that cannot be read) has none: None.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import VerifyStart
from hostpc.calibrate.run_header import read_run_header
from hostpc.errors import InputError
from hostpc.json_object import JsonObject

FIT_DATASET = "dataset.json"
VERIFY_DATASET = "verify_dataset.json"
FIELD = "measured_under"
"""FIT.json's key of the record (hostpc.calibrate.fit_file reads it)."""


@dataclass(frozen=True)
class MeasuredUnder:
    """run: the run folder (absolute); dataset: the dataset's file name in it;
    zero_offsets: (n,) rad, the controller's offsets its poses were measured under."""

    run: str
    dataset: str
    zero_offsets: tuple[float, ...]

    def to_json(self) -> JsonObject:
        return {"run": self.run, "dataset": self.dataset,
                "zero_offsets": list(self.zero_offsets)}


def measured_under(dataset: str | Path) -> MeasuredUnder | None:
    """The offsets the dataset file `dataset` was measured under, if it is a run folder's
    dataset.json or verify_dataset.json and the run's files say (see the module); None
    otherwise."""
    path = Path(dataset).resolve()
    journal = Journal(path.parent)
    if path.name not in (FIT_DATASET, VERIFY_DATASET) or not journal.exists:
        return None
    try:
        if path.name == FIT_DATASET:
            offsets = tuple(read_run_header(journal).initial.zero_offsets)
        else:
            started = journal.last(VerifyStart)
            if started is None:
                return None
            offsets = started.offsets
    except InputError:
        return None  # a run folder whose files do not say: nothing recorded
    return MeasuredUnder(str(path.parent), path.name, tuple(float(v) for v in offsets))


def measured_under_field(dataset: str | Path) -> JsonObject:
    """FIT.json's ``measured_under`` entry for a fit of `dataset` ({} when there is none)."""
    found = measured_under(dataset)
    return {} if found is None else {FIELD: found.to_json()}
