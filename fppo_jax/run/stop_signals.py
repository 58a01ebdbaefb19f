"""The signals a cluster sends a job it is about to stop, caught so that a checkpointed run
stops cleanly: SIGTERM on preemption, at its time limit and on scancel; SIGUSR1 when asked for
ahead of the time limit (``sbatch --signal=USR1@SECONDS``).

Light on purpose (no JAX): the command line catches them from its start, before it imports
anything heavy, and lets them go (:func:`let_go`) once it knows that its command does not
catch them; within that, the driver acts on them (:mod:`fppo_jax.run.training`), stopping with
:class:`StoppedBySignal`, and a tune or a study at its next safe point
(:func:`stop_if_signalled`), with :class:`StoppedAtSafePoint`.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

STOP_SIGNALS = (signal.SIGTERM, signal.SIGUSR1)

# The outermost `caught` block's, while one catches: what it received, and the handlers it
# replaced.
_received: list[int] | None = None
_previous: dict[int, Any] = {}


@contextlib.contextmanager
def caught(numbers: tuple[int, ...]) -> Iterator[list[int]]:
    """While the block runs, `numbers` are recorded in the list it is given instead of acting,
    and their handlers are then restored. Within a block that catches already, that block's
    list, which holds what came before this block began. Python handles signals in the main
    thread alone; and a signal whose handler was not installed from Python is left to it, as it
    could not be restored."""
    global _received
    if numbers and _received is not None:
        yield _received
        return
    received: list[int] = []
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for number in numbers:
            if signal.getsignal(number) is not None:
                previous[number] = signal.signal(number, lambda n, _: received.append(n))
    if previous:
        _received = received
        _previous.update(previous)
    try:
        yield received
    finally:
        if previous and _received is received:  # not let go of already
            let_go(act=False)


def let_go(act: bool = True) -> None:
    """Ends the outermost block's catching now, for a command that turns out to leave the
    signals their own action (no checkpoints; joined processes, where JAX's preemption service
    takes SIGTERM): the handlers it replaced are back, and where `act`, each signal it held
    meanwhile acts as it would have (the end of the process, by default). The block's end
    then restores nothing."""
    global _received
    held = _received or []
    for number, handler in _previous.items():
        signal.signal(number, handler)
    _previous.clear()
    _received = None
    for number in dict.fromkeys(held) if act else ():
        signal.raise_signal(number)


def signalled() -> int | None:
    """The first stop signal the outermost catching block received, if any."""
    return _received[0] if _received else None


def stop_if_signalled(said: str) -> None:
    """At a safe point of a tune or a study: raises :class:`StoppedAtSafePoint` if a stop
    signal came (`said` says where it stopped and how to go on)."""
    number = signalled()
    if number is not None:
        raise StoppedAtSafePoint(number, said)


class StoppedBySignal(Exception):
    """A checkpointed run stopped on SIGTERM or SIGUSR1 at the end of a chunk of updates, its
    checkpoint written, or before training if the signal came while it started or compiled
    (`trained` False), with nothing new checkpointed: resuming goes on from `update` (the
    newest checkpoint's, 0 if none)."""

    update: int | None

    def __init__(
        self, signal_number: int, update: int, checkpoint_dir: str | Path, trained: bool = True
    ):
        self.signal = signal.Signals(signal_number)
        self.update, self.trained = update, trained
        where = Path(checkpoint_dir).absolute()
        if trained:
            said = f"after update {update}, checkpointed in {where}; resume (--resume) to go on"
            said += " from there"
        else:
            said = "before training (while starting or compiling), nothing new checkpointed; "
            said += f"resume (--resume) to go on from the newest checkpoint in {where}, or from "
            said += "the start if there is none"
        super().__init__(f"stopped by {self.signal.name} {said}")


class StoppedAtSafePoint(StoppedBySignal):
    """A tune or a study stopped on SIGTERM or SIGUSR1 at its next safe point: after the
    compiled call in flight, or between rungs or groups of seeds, with what it finished
    recorded. The same call goes on from there, bit for bit; what `said` names was not
    recorded, and trains again. `update` is None: it goes on from its records, not from a
    checkpoint's update."""

    def __init__(self, signal_number: int, said: str):
        Exception.__init__(self, f"stopped by {signal.Signals(signal_number).name} {said}")
        self.signal = signal.Signals(signal_number)
        self.update, self.trained, self.said = None, True, said
