"""A simulator process started before hostpc knows it needs one, to overlap start-ups.

`hostpc calibrate --robot sim` spends its first ~0.5 s importing and checking its options,
and the simulator it then starts spends ~0.4 s importing its own modules before it listens.
`prestart` (called by hostpc/cli/main.py before the command's imports) starts
`python -m controller_stub.warm`, which does its imports at once and then waits for one line
on stdin (controller_stub/warm.py); `SimulatedController.start` (simulator.py) hands it the
same `serve` arguments, token and log it would give a fresh process (`hand_over`), or starts
a fresh one when there is no warm process. A warm process nobody took is ended by `discard`
(terminated). `wait_for_exit` waits for a simulator's end without polling. Standard
library only: this module is imported before everything else, by every command, so what
only a started process needs (subprocess with its threading, selectors and signal) is
imported where it is used.

On Linux the process gets PR_SET_PDEATHSIG (SIGTERM): if hostpc dies, even by SIGKILL, the
simulator is terminated too.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import subprocess

PR_SET_PDEATHSIG = 1
"""prctl option (linux/prctl.h): the signal this process gets when its parent dies."""

_warm: subprocess.Popen[str] | None = None


def die_with_parent() -> Callable[[], None] | None:
    """A preexec_fn that makes the child get SIGTERM when hostpc dies (Linux prctl
    PR_SET_PDEATHSIG), or None where that does not exist."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        prctl = libc.prctl
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        if os.getppid() != parent:  # the parent died before prctl took effect
            os.kill(os.getpid(), signal.SIGTERM)

    return preexec


def wants_simulator(command: str | None, words: Sequence[str]) -> bool:
    """Whether the command line `words` starts a simulator: `hostpc calibrate --robot sim`
    (not with --help or --check, which connect to nothing)."""
    if command != "calibrate" or any(w in ("-h", "--help", "--check") for w in words):
        return False
    return "--robot=sim" in words or any(
        a == "--robot" and b == "sim" for a, b in zip(words, words[1:], strict=False))


def prestart() -> None:
    """Start a warm simulator process (once) for `take`."""
    global _warm
    if _warm is not None and _warm.poll() is None:
        return
    import subprocess

    with contextlib.suppress(OSError):
        _warm = subprocess.Popen(
            [sys.executable, "-m", "controller_stub.warm"], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
            preexec_fn=die_with_parent(),  # noqa: PLW1509
        )


def take() -> subprocess.Popen[str] | None:
    """The warm process, if one is running (it is the caller's from then on)."""
    global _warm
    process, _warm = _warm, None
    if process is not None and process.poll() is not None:
        _close(process)
        return None
    return process


def hand_over(process: subprocess.Popen[str], argv: Sequence[str], env: Mapping[str, str],
              stderr: Path) -> bool:
    """Tell the warm `process` to run `controller-stub ARGV` with `env` added to its
    environment and its stderr appended to `stderr`; False if it is gone (then ended)."""
    assert process.stdin is not None
    order = {"argv": list(argv), "env": dict(env), "stderr": str(stderr)}
    try:
        process.stdin.write(json.dumps(order) + "\n")
        process.stdin.close()
    except (OSError, ValueError):
        process.kill()
        process.wait()
        _close(process)
        return False
    return True


def discard() -> None:
    """End a warm process nobody took (terminated: it has served nothing)."""
    process = take()
    if process is None:
        return
    import subprocess

    process.terminate()
    try:
        wait_for_exit(process, timeout=5)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
    _close(process)


def wait_for_exit(process: subprocess.Popen[str], timeout: float) -> int:
    """`process.wait(timeout)`, woken the moment the process ends (a pidfd, Linux): Popen's
    own wait polls with sleeps growing to 50 ms, which hostpc would spend after every run's
    simulator ended. subprocess.TimeoutExpired if it has not ended within `timeout` s."""
    import subprocess

    try:
        handle = os.pidfd_open(process.pid)
    except (AttributeError, OSError):  # not Linux, or the process is reaped already
        return process.wait(timeout=timeout)
    try:
        ended = select.select([handle], [], [], timeout)[0]
    finally:
        os.close(handle)
    if not ended:
        raise subprocess.TimeoutExpired(process.args, timeout)
    return process.wait()  # it has ended: reaped at once


def _close(process: subprocess.Popen[str]) -> None:
    for stream in (process.stdin, process.stdout):
        if stream is not None:
            with contextlib.suppress(OSError, ValueError):
                stream.close()
