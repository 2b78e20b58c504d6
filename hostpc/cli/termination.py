"""SIGTERM and Ctrl-C for long commands (`hostpc calibrate`): a SIGTERM is raised like
Ctrl-C (`Terminated`, a KeyboardInterrupt), so every `with` and `finally` block runs (the
simulated controller is stopped, the robot link closed); inside the event loop it cancels the
main task instead of raising into whatever frame runs. Exit codes as a shell reports them."""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Coroutine, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

T = TypeVar("T")

EXIT_INTERRUPTED = 130  # Ctrl-C, as a shell reports it
EXIT_TERMINATED = 143  # SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every `with` and `finally` block runs (the
    simulated controller is stopped, the robot link closed)."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated(f"signal {signum}")


async def cancel_on_sigterm(run: Coroutine[Any, Any, T]) -> T:
    """Await `run`; a SIGTERM meanwhile cancels it at its next await and raises Terminated.

    Inside the event loop a signal must not raise into whatever frame happens to run (it can
    land in the transport's reader task and read as a lost link); the loop's own signal
    handler cancels the main task cleanly instead, and every `finally` still runs. A motion
    in progress is aborted by the client (hostpc.transport.client) before it lets the
    cancellation go on; its note ("move_joints interrupted: abort sent: motion stopped") is
    carried onto the Terminated, or the KeyboardInterrupt of a Ctrl-C (`interrupt_notes`)."""
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    terminated = False

    def on_sigterm() -> None:
        nonlocal terminated
        terminated = True
        if task is not None:
            task.cancel()

    try:
        loop.add_signal_handler(signal.SIGTERM, on_sigterm)
    except (NotImplementedError, RuntimeError, ValueError):  # not the main thread
        return await run
    try:
        return await run
    except asyncio.CancelledError as exc:
        notes = getattr(exc, "__notes__", [])
        if terminated:
            interrupt: KeyboardInterrupt = Terminated(f"signal {int(signal.SIGTERM)}")
        elif notes:  # Ctrl-C (asyncio.run cancels the task): keep what the client did
            interrupt = KeyboardInterrupt()
        else:
            raise
        for note in notes:
            interrupt.add_note(note)
        raise interrupt from None
    finally:
        loop.remove_signal_handler(signal.SIGTERM)
        signal.signal(signal.SIGTERM, _raise_terminated)  # back to the synchronous handler


def interrupt_notes(interrupt: BaseException) -> str:
    """What was done about the motion an interrupt cut short ("" when none was moving)."""
    return "; ".join(getattr(interrupt, "__notes__", []))


@contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """While inside: SIGTERM raises `Terminated` (a KeyboardInterrupt), and SIGINT raises
    KeyboardInterrupt even where the process inherited it ignored (a command started in the
    background by a shell script, `cmd &`, or by a station that was: Python then keeps
    SIGINT ignored and asyncio.run installs no handler, so Ctrl-C and the station's
    "stop at a safe point" did nothing while the run went on to push). Outside the main
    thread (no signal handlers there) it does nothing."""
    try:
        previous = signal.signal(signal.SIGTERM, _raise_terminated)
        previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
        signal.signal(signal.SIGINT, previous_int)
