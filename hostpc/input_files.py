"""Opening the files hostpc reads: regular files only, each kind with a size limit.

Every file a command reads from the user (a dataset, a saved fit, a URDF, a metrology CSV,
a plugin, a rig file, a scenario or station or cell file) is opened here, so that nothing
reads without bound or waits forever:

- a FIFO, a device (``/dev/zero``), a socket or a directory is refused with one line before
  anything is read: ``os.stat`` first, then ``open`` with ``O_NONBLOCK`` (opening a FIFO
  with no writer would block) and ``fstat`` on the open descriptor, so a file swapped for a
  FIFO between the two checks is refused too;
- a regular file larger than its kind's limit is refused from its size, before reading;
  the limits are generous (docs/security.md) and each can be raised with
  ``$ZEROCAL_MAX_<KIND>_MB`` (e.g. ``ZEROCAL_MAX_DATASET_MB``, ``ZEROCAL_MAX_CSV_MB``);
- reading stops one byte past the limit, so a file that grows while it is read is refused
  as well.

Every refusal is the kind's error class (``InputError``, ``DatasetError`` for datasets:
CLI exit code 2) with one line naming the file.
"""

from __future__ import annotations

import fcntl
import math
import os
import stat
from dataclasses import dataclass
from typing import BinaryIO

from hostpc.errors import DatasetError, InputError

PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class InputKind:
    """One kind of input file: its name (the ``$ZEROCAL_MAX_<NAME>_MB`` variable), what the
    messages call it, its default size limit (MB, 1e6 bytes) and its error class."""

    name: str
    noun: str
    default_mb: float
    error: type[InputError] = InputError

    @property
    def env(self) -> str:
        """The environment variable that raises (or lowers) this kind's limit."""
        return f"ZEROCAL_MAX_{self.name.upper()}_MB"

    def limit_bytes(self) -> int:
        """The size limit in bytes (``$ZEROCAL_MAX_<NAME>_MB``, else the default)."""
        text = os.environ.get(self.env)
        if text is None or not text.strip():
            return int(self.default_mb * 1e6)
        try:
            megabytes = float(text)
        except ValueError:
            megabytes = math.nan
        if not (math.isfinite(megabytes) and megabytes > 0):
            raise InputError(f"${self.env}={text!r}: expected a positive number of MB")
        return int(megabytes * 1e6)


DATASET = InputKind("dataset", "dataset file", 512.0, DatasetError)
"""A zerocal-dataset/1 file: the largest real ones (10^5 samples) are tens of MB."""
FIT = InputKind("fit", "fit file", 64.0)
"""The output of `hostpc fit --json` (a few kB to a few MB)."""
URDF = InputKind("urdf", "URDF", 64.0)
"""A URDF robot description (meshes are not read)."""
CSV = InputKind("csv", "CSV file", 20_000.0)
"""A metrology CSV for `hostpc import` (streamed; tracker logs can be GB)."""
PLUGIN = InputKind("plugin", "plugin", 16.0)
"""A Python file given with --plugin."""
RIG = InputKind("rig", "rig file", 16.0)
"""A stereo rig calibration (JSON)."""
CONFIG = InputKind("config", "file", 16.0)
"""Scenario, station and cell files (YAML/JSON) and run documents read back (result.json)."""


def _file_type(mode: int) -> str | None:
    """What a non-regular file is ("a FIFO", ...), or None for a regular file."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "not a regular file"


def _refuse_non_regular(mode: int, source: str, kind: InputKind) -> None:
    what = _file_type(mode)
    if what == "a directory":
        raise kind.error(f"{source}: is a directory, not a {kind.noun}")
    if what is not None:
        raise kind.error(f"{source}: not a regular file ({what}); give a {kind.noun}")


def _too_large(source: str, size: int | None, limit: int, kind: InputKind) -> InputError:
    what = f"{size / 1e6:.1f} MB" if size is not None else "more than that"
    return kind.error(f"{source}: {what}, above the {kind.name} size limit of {limit / 1e6:g} "
                      f"MB (set ${kind.env} to raise it)")


def _cannot_read(source: str, kind: InputKind, exc: OSError) -> InputError:
    if isinstance(exc, FileNotFoundError):
        if kind is DATASET:
            return kind.error(f"{source}: file not found")
        return kind.error(f"{source}: cannot read {kind.noun} (no such file)")
    return kind.error(f"{source}: cannot read {kind.noun} ({exc.strerror or exc})")


def open_input(path: PathLike, kind: InputKind, source: str | None = None) -> BinaryIO:
    """Open a regular file for reading in binary; the caller closes it.

    Refuses (``kind.error``, one line naming ``source``, default the path) a missing or
    unreadable file, anything but a regular file, and a file above the kind's size limit;
    nothing is read. A caller that streams the file (CSV import) reads it from the handle;
    one that wants it whole calls `read_input_bytes`."""
    source = os.fspath(path) if source is None else source
    limit = kind.limit_bytes()
    try:
        _refuse_non_regular(os.stat(path).st_mode, source, kind)
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise _cannot_read(source, kind, exc) from None
    try:
        status = os.fstat(fd)
        _refuse_non_regular(status.st_mode, source, kind)  # swapped after the stat
        if status.st_size > limit:
            raise _too_large(source, status.st_size, limit, kind)
        flags = fcntl.fcntl(fd, fcntl.F_GETFL)
        fcntl.fcntl(fd, fcntl.F_SETFL, flags & ~os.O_NONBLOCK)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def check_input_file(path: PathLike, kind: InputKind, source: str | None = None) -> None:
    """Refuse what `open_input` refuses, reading nothing: for a reader that opens the file
    itself (the plugin importer, the CSV importer's own streaming)."""
    open_input(path, kind, source).close()


def read_input_bytes(path: PathLike, kind: InputKind, source: str | None = None) -> bytes:
    """The whole content of a regular file within the kind's size limit (see `open_input`);
    a file that grows past the limit while it is read is refused too."""
    source = os.fspath(path) if source is None else source
    limit = kind.limit_bytes()
    with open_input(path, kind, source) as handle:
        try:
            data = handle.read(limit + 1)
        except OSError as exc:
            raise _cannot_read(source, kind, exc) from None
    if len(data) > limit:
        raise _too_large(source, None, limit, kind)
    return data


def read_input_text(path: PathLike, kind: InputKind, source: str | None = None,
                    encoding: str = "utf-8") -> str:
    """`read_input_bytes` decoded (``utf-8-sig`` drops a byte-order mark); a file that is
    not text in that encoding is refused naming the byte."""
    source = os.fspath(path) if source is None else source
    data = read_input_bytes(path, kind, source)
    try:
        return data.decode(encoding)
    except UnicodeDecodeError as exc:
        raise kind.error(f"{source}: not UTF-8 text (byte {exc.start})") from None
