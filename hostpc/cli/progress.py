"""Progress on stderr: one updating line on a terminal, plain lines otherwise.

    [ 12.3s] measure  [##########..........]  31/60  fit pose 31/60

On a terminal (TTY) the line is redrawn in place (carriage return) and messages are printed
above it; when stderr is a file or a pipe, each stage and every tenth of a stage is one
plain line, so logs stay readable.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

BAR_WIDTH = 24


class StderrProgress:
    """A `hostpc.methods.base.Progress` drawing on a text stream (default stderr)."""

    def __init__(self, stream: TextIO | None = None, quiet: bool = False) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.quiet = quiet
        self.start = time.monotonic()
        self.name = ""
        self.total: int | None = None
        self.done = 0
        self.note = ""
        self._last_tenth = -1
        self._drawn = False

    def _elapsed(self) -> str:
        return f"[{time.monotonic() - self.start:6.1f}s]"

    def _line(self) -> str:
        if self.total:
            filled = int(BAR_WIDTH * min(self.done, self.total) / self.total)
            bar = "#" * filled + "." * (BAR_WIDTH - filled)
            return (f"{self._elapsed()} {self.name:<8} [{bar}] {self.done:>4}/{self.total}"
                    f"  {self.note}")
        return f"{self._elapsed()} {self.name}"

    def _write(self, text: str) -> None:
        if self.quiet:
            return
        self.stream.write(text)
        self.stream.flush()

    def _clear(self) -> None:
        if self.tty and self._drawn:
            self._write("\r\x1b[2K")
            self._drawn = False

    def _draw(self) -> None:
        if self.tty:
            self._write("\r\x1b[2K" + self._line()[:200])
            self._drawn = True

    def stage(self, name: str, total: int | None = None) -> None:
        """Start a stage."""
        self.name, self.total, self.done, self.note = name, total, 0, ""
        self._last_tenth = -1
        if self.tty:
            self._draw()
        else:
            self._write(f"{self._elapsed()} {name}" + (f" ({total})" if total else "") + "\n")

    def advance(self, done: int, note: str = "") -> None:
        """`done` steps of the stage are finished."""
        self.done, self.note = done, note
        if self.tty:
            self._draw()
        elif self.total:
            tenth = int(10 * done / self.total)
            if tenth != self._last_tenth and (tenth > self._last_tenth):
                self._last_tenth = tenth
                self._write(f"{self._elapsed()} {self.name} {done}/{self.total}\n")

    def message(self, text: str) -> None:
        """A line kept above the progress line."""
        self._clear()
        self._write(f"{text}\n")
        self._draw()

    def close(self) -> None:
        """Clear the updating line."""
        self._clear()
