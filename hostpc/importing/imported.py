"""The samples of an imported CSV held as columns, and the dataset document written from them.

A dict per sample (lists of Python floats) costs about a kilobyte a row, so a million-row
tracker export would need a gigabyte before the frame guess starts; columns of float64 cost
about 100 bytes a row. The document is written to the file one sample at a time
(:func:`write_document`), so it is never held as one string either.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

__all__ = ["ImportedSamples", "write_document"]

FloatArray = NDArray[np.float64]
_CHUNK = 10_000  # rows turned into Python lists at a time while writing
_SAMPLES_SLOT = "@zerocal-samples@"  # where write_document splices the samples in


@dataclass(frozen=True)
class ImportedSamples:
    """Every sample of one CSV, in SI units, one array per field.

    q ``(N, ndof)`` rad (m for prismatic joints); p ``(N, 3)`` m, in the world frame;
    sigma ``(N,)`` m; t ``(N,)`` s or None; world_pose: rpy ``(N, 3)`` rad and one
    sigma_angle (rad); world_point with a marker column: marker_index ``(N,)`` into
    marker_names (in order of first appearance)."""

    method: str
    source: str
    q: FloatArray
    p: FloatArray
    sigma: FloatArray
    t: FloatArray | None = None
    rpy: FloatArray | None = None
    sigma_angle: float | None = None
    marker_index: NDArray[np.int64] | None = None
    marker_names: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.q)

    def sample_dicts(self) -> Iterator[dict[str, Any]]:
        """The samples as the dataset file's objects (keys in the file's order), built a
        chunk at a time."""
        for start in range(0, len(self), _CHUNK):
            part = slice(start, start + _CHUNK)
            columns: list[tuple[str, list[Any]]] = [
                ("q", self.q[part].tolist()), ("p", self.p[part].tolist()),
                ("sigma", self.sigma[part].tolist())]
            if self.t is not None:
                columns.append(("t", self.t[part].tolist()))
            if self.rpy is not None:
                columns.append(("rpy", self.rpy[part].tolist()))
                columns.append(("sigma_angle", [self.sigma_angle] * len(columns[0][1])))
            elif self.marker_index is not None:
                columns.append(("marker", [self.marker_names[k]
                                           for k in self.marker_index[part].tolist()]))
            keys = [key for key, _ in columns]
            for values in zip(*(column for _, column in columns), strict=True):
                yield dict(zip(keys, values, strict=True))


def write_document(out: TextIO, head: Mapping[str, Any], samples: ImportedSamples) -> None:
    """Write ``head`` with ``samples`` to ``out``: the head indented, one sample per line."""
    text = json.dumps({**head, "samples": _SAMPLES_SLOT}, indent=1)
    before, after = text.split(json.dumps(_SAMPLES_SLOT), 1)
    out.write(before + "[")
    separator = "\n  "
    for sample in samples.sample_dicts():
        out.write(separator + json.dumps(sample))
        separator = ",\n  "
    out.write("\n ]" + after + "\n")
