"""SIGTERM handled like Ctrl-C, so a long command ends the way an interrupted one should.

`kill` and cluster schedulers send SIGTERM, and a background job ignores Ctrl-C; Python's default for
SIGTERM ends the process on the spot, skipping every ``finally``: worker processes are orphaned, and
nothing is saved. Inside `sigterm_as_ctrl_c` the signal raises KeyboardInterrupt instead, so the same
cleanup that Ctrl-C gets (save the run, end the workers, remove unfinished files) runs.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


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
