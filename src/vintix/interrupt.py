"""Stopping a long command safely: SIGTERM handled like Ctrl-C, and loops that stop between steps.

`kill` and cluster schedulers send SIGTERM, and a background job ignores Ctrl-C; Python's default for
SIGTERM ends the process on the spot, skipping every ``finally``: worker processes are orphaned, and
nothing is saved. Inside `sigterm_as_ctrl_c` the signal raises KeyboardInterrupt instead, so the same
cleanup that Ctrl-C gets (save the run, end the workers, remove unfinished files) runs. A loop whose state
is only whole between two steps (an optimizer step half applied is not a checkpoint) uses `stop_requests`
instead: the first Ctrl-C or SIGTERM is a request it reads after each step, a second one interrupts at once.
After saving, such a command raises `Interrupted`, whose message says what was saved and how to go on.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType


class Interrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM after the command saved its work; the message says where, and how to resume."""


@contextmanager
def sigterm_as_ctrl_c() -> Iterator[None]:
    """Raise KeyboardInterrupt on SIGTERM while the block runs. Python takes signals in the main thread
    only; elsewhere SIGTERM keeps its default."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class StopRequest:
    """Whether a stop was asked for (`stop_requests`), and by which signal."""

    def __init__(self) -> None:
        self.signal: str | None = None

    def __bool__(self) -> bool:
        return self.signal is not None


@contextmanager
def stop_requests() -> Iterator[StopRequest]:
    """While the block runs, the first SIGINT (Ctrl-C) or SIGTERM only sets the yielded request (and says that the
    command stops after its current step); a second one raises KeyboardInterrupt at once.
    Outside the main thread (where Python takes no signals) the request is never set."""
    request = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield request
        return

    def ask(signum: int, frame: FrameType | None) -> None:
        if request:
            raise KeyboardInterrupt
        request.signal = signal.Signals(signum).name
        print(f"\n{request.signal}: stopping after this step to save it (again to stop at once, unsaved)", flush=True)

    previous = {s: signal.signal(s, ask) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield request
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
