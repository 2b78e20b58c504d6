"""Read a metrology CSV as a stream: the header first, then the data rows one at a time.

A tracker export may have millions of rows; holding the file's text, a list of its lines and
a tuple per row at once took several times the file's size. Here the header is read and
checked on construction and the rows are yielded lazily from the open file, so memory does
not grow with the file (the caller keeps only the numbers it needs).

Delimiter: comma, semicolon or tab, sniffed from the header line. A header cell may carry its
unit in brackets or parentheses, ``x [mm]`` or ``q1 (deg)``: the column is named without it
and the unit is kept in :attr:`CsvHeader.units`. Every error is an
:class:`~hostpc.errors.InputError` naming the file and the row (the file's line number; the
header is row 1).
"""

from __future__ import annotations

import csv
import itertools
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from hostpc.errors import InputError

__all__ = ["CsvHeader", "CsvRows", "Row", "read_csv"]

_UNIT_SUFFIX = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*$")

#: one data row: (file line number, stripped cells)
Row = tuple[int, tuple[str, ...]]


@dataclass(frozen=True)
class CsvHeader:
    """A CSV file's column names (unit suffixes removed) and the units its header names."""

    source: str
    columns: tuple[str, ...]
    units: Mapping[str, str]  # column -> unit named in its header
    delimiter: str = ","  # the field separator sniffed from the header line


@dataclass(frozen=True)
class CsvRows:
    """The header of a CSV stream and an iterator over its non-blank data rows (read once);
    blank: the rows (line numbers) skipped as blank between the header and the last data
    row read so far (a pose not written; blank lines at the end are not counted); cut: once
    the rows are read, the last data row's line number if the file ends in it without a
    line end (a file copied while it was written: its last value may be cut short)."""

    header: CsvHeader
    rows: Iterator[Row]
    blank: list[int] = field(default_factory=list)
    cut: list[int] = field(default_factory=list)


def _parse_header(cells: list[str], source: str, delimiter: str = ",") -> CsvHeader:
    columns: list[str] = []
    units: dict[str, str] = {}
    for k, cell in enumerate(cells):
        name = cell.strip().lstrip("\ufeff")
        match = _UNIT_SUFFIX.match(name)
        if match:
            name = match.group(1)
            units[name] = match.group(2)
        if not name:
            raise InputError(f"{source}: row 1, column {k + 1}: empty column name")
        if name in columns:
            raise InputError(f"{source}: row 1, column {k + 1}: {name!r} appears twice")
        columns.append(name)
    return CsvHeader(source=source, columns=tuple(columns), units=units, delimiter=delimiter)


def _tracked(lines: Iterator[str], last: list[str]) -> Iterator[str]:
    """``lines``, keeping the latest in ``last`` (one item)."""
    for line in lines:
        last[:] = [line]
        yield line


def _data_rows(reader: Any, source: str, blank: list[int], last: list[str],
               cut: list[int]) -> Iterator[Row]:
    pending: list[int] = []
    try:
        for cells in reader:
            if not any(c.strip() for c in cells):
                pending.append(reader.line_num)
                continue
            blank.extend(pending)
            pending.clear()
            yield reader.line_num, tuple(c.strip() for c in cells)
        if not pending and last and not last[0].endswith(("\n", "\r")):
            cut.append(reader.line_num)
    except csv.Error as exc:
        raise InputError(f"{source}: row {reader.line_num}: {exc}") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{source}: row {reader.line_num + 1}: not UTF-8 text ({exc.reason})"
                         ) from None


def read_csv(lines: Iterable[str], source: str) -> CsvRows:
    """The header of ``lines`` (an open text file, ideally opened with ``newline=""``, or any
    iterable of lines) read now, its data rows lazily; InputError for an empty file or a bad
    header."""
    line_iter = iter(lines)
    try:
        first = next(line_iter, "")
    except UnicodeDecodeError as exc:
        raise InputError(f"{source}: row 1: not UTF-8 text ({exc.reason})") from None
    if not first.strip():
        if not any(line.strip() for line in line_iter):
            raise InputError(f"{source}: empty file")
        raise InputError(f"{source}: row 1: the header is empty (the first line must name "
                         "the columns)")
    try:
        dialect: Any = csv.Sniffer().sniff(first.rstrip("\r\n"), delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    last: list[str] = []
    reader = csv.reader(_tracked(itertools.chain([first], line_iter), last), dialect)
    try:
        header = next(reader)
    except (StopIteration, csv.Error) as exc:
        raise InputError(f"{source}: row 1: cannot read the header ({exc})") from None
    blank: list[int] = []
    cut: list[int] = []
    return CsvRows(header=_parse_header(header, source, str(dialect.delimiter)),
                   rows=_data_rows(reader, source, blank, last, cut), blank=blank, cut=cut)
