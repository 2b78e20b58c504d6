"""The samples of an imported CSV held as columns, and the dataset document written from them.

A dict per sample (lists of Python floats) costs about a kilobyte a row, so a million-row
tracker export would need a gigabyte before the frame guess starts; columns of float64 cost
about 100 bytes a row. The document is written to the file one sample at a time
(:func:`write_document`), so it is never held as one string either.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from hostpc.json_object import JsonObject

__all__ = ["ImportedSamples", "write_document"]

FloatArray = NDArray[np.float64]
_CHUNK = 10_000  # rows turned into Python lists at a time while writing
_SAMPLES_SLOT = "@zerocal-samples@"  # where write_document splices the samples in


@dataclass(frozen=True)
class ImportedSamples:
    """Every sample of one CSV, in SI units, one array per field.

    q ``(N, ndof)`` rad (m for prismatic joints); p ``(N, 3)`` m, in the world frame;
    sigma ``(N,)`` m; sigma_xyz ``(N, 3)`` m or None: per-axis sigmas, written as a diagonal
    ``cov`` instead of ``sigma`` (sigma is then their rms); t ``(N,)`` s or None;
    temperature ``(N,)`` as written, or None; world_pose: rpy ``(N, 3)`` rad and one
    sigma_angle (rad); world_point with markers: marker_index ``(N,)`` into marker_names
    (in order of first appearance, or of the ``marker.NAME`` groups)."""

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
    sigma_xyz: FloatArray | None = None
    temperature: FloatArray | None = None
    warnings: tuple[str, ...] = ()
    """What the import noticed but did not refuse (repeated rows, blank rows dropped):
    one line each, printed by the CLI."""

    def __len__(self) -> int:
        return len(self.q)

    def sample_dicts(self) -> Iterator[JsonObject]:
        """The samples as the dataset file's objects (keys in the file's order), built a
        chunk at a time."""
        for start in range(0, len(self), _CHUNK):
            part = slice(start, start + _CHUNK)
            columns: list[tuple[str, list[Any]]] = [
                ("q", self.q[part].tolist()), ("p", self.p[part].tolist())]
            if self.sigma_xyz is None:
                columns.append(("sigma", self.sigma[part].tolist()))
            else:
                columns.append(("cov", self._covariances(self.sigma_xyz[part])))
            if self.t is not None:
                columns.append(("t", self.t[part].tolist()))
            if self.temperature is not None:
                columns.append(("temperature", self.temperature[part].tolist()))
            if self.rpy is not None:
                columns.append(("rpy", self.rpy[part].tolist()))
                if self.sigma_xyz is None:
                    columns.append(("sigma_angle", [self.sigma_angle] * len(columns[0][1])))
            elif self.marker_index is not None:
                columns.append(("marker", [self.marker_names[k]
                                           for k in self.marker_index[part].tolist()]))
            keys = [key for key, _ in columns]
            for values in zip(*(column for _, column in columns), strict=True):
                yield dict(zip(keys, values, strict=True))

    def _covariances(self, sigma_xyz: FloatArray) -> list[Any]:
        """Diagonal covariances of per-axis sigmas: 3x3 (world_point), or 6x6 with the
        orientation's sigma_angle (world_pose, whose file takes ``cov`` or ``sigma`` and
        ``sigma_angle``, not a mix)."""
        variances = sigma_xyz**2
        if self.rpy is not None:
            assert self.sigma_angle is not None
            variances = np.column_stack([variances, np.full((len(variances), 3),
                                                            self.sigma_angle**2)])
        size = variances.shape[1]
        cov = np.zeros((len(variances), size, size))
        cov[:, np.arange(size), np.arange(size)] = variances
        return list(cov.tolist())


def write_document(out: TextIO, head: JsonObject, samples: ImportedSamples) -> None:
    """Write ``head`` with ``samples`` to ``out``: the head indented, one sample per line."""
    text = json.dumps({**head, "samples": _SAMPLES_SLOT}, indent=1)
    before, after = text.split(json.dumps(_SAMPLES_SLOT), 1)
    out.write(before + "[")
    separator = "\n  "
    for sample in samples.sample_dicts():
        out.write(separator + json.dumps(sample))
        separator = ",\n  "
    out.write("\n ]" + after + "\n")
