"""How runs are driven, apart from what they train: the host-side options that ``train`` and
``sweep`` share (:class:`Options`, each field declared once with its default, its check and
its command-line help, from which ``fppo-jax`` makes its flags), and what a callback sees
between compiled chunks (:class:`Snapshot`)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from fppo_jax.core.checks import positive_int
from fppo_jax.errors import InvalidInput, install_hint

if TYPE_CHECKING:  # the trainer, not needed to declare or check options (the command's flags)
    from fppo_jax.core.policy import Policy
    from fppo_jax.core.trainer import TrainState
    from fppo_jax.run.progress import Progress


class Snapshot(NamedTuple):
    """What a callback sees between compiled chunks.

    `update` counts the updates done; `metrics` holds every update so far (``[run, update]``
    for a sweep's group of runs, whose indices in the sweep are `runs`); `state` is the
    training state and `policy` its policy (both batched along runs in a sweep).
    """

    update: int
    metrics: dict[str, np.ndarray]
    state: TrainState
    policy: Policy
    runs: range


Callback = Callable[[Snapshot], bool | None]


def _flag(help: str, metavar: str | None = None, flag: str | None = None) -> dict[str, str | None]:
    """An :class:`Options` field's command-line flag: its help, its metavar, and its name if it
    is not the field's (``log_dir``'s is ``--output``)."""
    return {"help": help, "metavar": metavar, "flag": flag}


def callback_stops(answer: object) -> bool:
    """Whether a callback's answer stops training: ``False`` (Python's or numpy's) stops, ``True``
    and ``None`` go on, anything else is a mistake named at its first return."""
    if answer is None:
        return False
    if isinstance(answer, bool | np.bool_):
        return not answer
    raise TypeError(
        f"the callback returned {answer!r} ({type(answer).__name__}); it must return True or "
        "False (a Python or numpy boolean; False stops training), or None to go on"
    )


@dataclasses.dataclass(frozen=True)
class Options:
    """How runs are driven, apart from what they train: the host-side settings that ``train``
    and ``sweep`` share, as keyword arguments of either. Checked when made, before anything is
    compiled.

    `progress`: ``True`` shows a progress bar on a terminal, or prints a line per chunk of
    updates on stderr otherwise; a callable receives a :class:`~fppo_jax.run.progress.Progress`;
    ``False`` (with nothing else between chunks) runs the whole training as one compiled call.

    `checkpoint_dir`: save the full training state there every `checkpoint_every` updates
    (default: a twentieth of the run), keeping the newest `keep` (see
    :mod:`fppo_jax.store.checkpoint`). With ``resume=True`` training continues from the newest
    intact checkpoint there, if any, and ends exactly as if it had never stopped; a checkpoint
    of a differently configured run is refused with the differing fields named. Without
    `resume`, a directory that already holds checkpoints is refused, so that none is
    overwritten. A finished run goes on for more steps when resumed with a larger
    ``total_steps``, unless its learning rate anneals over the run (refused, with the reason).

    `log_dir`: write ``config.json`` (every setting, the versions and devices) there at once,
    then ``metrics.csv`` and TensorBoard event files as training goes. It is made and checked
    writable before compiling; one that holds a run's outputs is refused, unless `resume`
    continues the run whose ``config.json`` it is (the checkpoint's, or this run's if there is
    no checkpoint yet). `wandb_project` logs the same to Weights & Biases
    (the ``wandb`` extra).

    Environments whose state lives outside JAX (native MuJoCo, Gymnasium) cannot be
    checkpointed: a resumed run goes on from the restored policy, optimiser and normalisers with
    every environment starting a new episode, so it learns on but is not bitwise the run that
    never stopped (it says so on resuming).

    `devices`: how many of the devices JAX sees (default: all; one for the environments
    stepped on the host: native MuJoCo, Gymnasium) share the runs (see
    :mod:`fppo_jax.run.distributed`). In a multi-process run only process 0 reports and writes,
    checkpoints included: every process hands it its part of the state to save, and it hands
    each its part back on resuming.

    `callback(snapshot)` is called between compiled chunks with a :class:`Snapshot`; returning
    ``False`` (or a numpy ``False``, as a comparison of metrics gives) stops training there
    (checkpointed, if checkpoints are on), and the result holds the updates done; ``True`` or
    ``None`` goes on, and any other answer is a ``TypeError`` that names it. Every
    `eval_every` updates, and at the end, the deterministic policy plays `eval_episodes`
    episodes and their mean return is recorded as the metric ``eval_return`` (NaN between
    evaluations).
    """

    progress: bool | Callable[[Progress], None] = False
    log_dir: str | Path | None = dataclasses.field(
        default=None,
        metadata=_flag(
            "directory for config.json (at once), metrics.csv and TensorBoard files (as "
            "training goes) and the results",
            flag="--output",
        ),
    )
    checkpoint_dir: str | Path | None = dataclasses.field(
        default=None,
        metadata=_flag(
            "save the full training state in DIR every --checkpoint-every updates", "DIR"
        ),
    )
    resume: bool = dataclasses.field(
        default=False,
        metadata=_flag(
            "continue from the newest intact checkpoint in --checkpoint-dir (if there is one); "
            "with a larger --steps, a finished run goes on"
        ),
    )
    checkpoint_every: int | None = dataclasses.field(
        default=None,
        metadata=_flag("updates between checkpoints (default: a twentieth of the run)", "N"),
    )
    keep: int = dataclasses.field(default=3, metadata=_flag("checkpoints kept (the newest)"))
    eval_every: int | None = dataclasses.field(
        default=None,
        metadata=_flag(
            "every N updates and at the end, record eval_return: the deterministic policy's "
            "mean return over --eval-episodes episodes",
            "N",
        ),
    )
    eval_episodes: int = dataclasses.field(default=10, metadata=_flag("episodes per evaluation"))
    wandb_project: str | None = dataclasses.field(
        default=None,
        metadata=_flag(
            f"also log to this Weights & Biases project ({install_hint('wandb')}; "
            "WANDB_MODE=offline works without an account)",
            "NAME",
        ),
    )
    devices: int | None = dataclasses.field(
        default=None,
        metadata=_flag(
            "devices to train on (default: all that JAX sees, every process's in a "
            "multi-process run)",
            "N",
        ),
    )
    callback: Callback | None = None

    def __post_init__(self) -> None:
        for name in ("resume",):
            if not isinstance(getattr(self, name), bool | np.bool_):
                raise InvalidInput(f"{name} must be True or False, got {getattr(self, name)!r}")
        if not (isinstance(self.progress, bool | np.bool_) or callable(self.progress)):
            raise InvalidInput(f"progress must be True, False or a callable, got {self.progress!r}")
        if self.callback is not None and not callable(self.callback):
            raise InvalidInput(f"callback must be a callable, got {self.callback!r}")
        object.__setattr__(self, "keep", positive_int("keep", self.keep))
        positive_int("eval_episodes", self.eval_episodes)
        for name in ("checkpoint_every", "eval_every", "devices"):
            if getattr(self, name) is not None:
                positive_int(name, getattr(self, name))
        for name in ("checkpoint_dir", "log_dir"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, str | os.PathLike):
                raise InvalidInput(f"{name} must be a path, got {value!r}")
            if value is not None and os.fspath(value) == "":
                raise InvalidInput(f"{name} is an empty path: name a directory ('.' for this one)")
        if self.checkpoint_dir is not None and self.log_dir is not None:
            where = Path(self.log_dir).absolute()
            if Path(self.checkpoint_dir).absolute() == where:
                raise InvalidInput(
                    "checkpoint_dir and log_dir (--checkpoint-dir and --output) name the same "
                    f"directory, {where}: give each its own"
                )
        if self.checkpoint_dir is None and (self.resume or self.checkpoint_every is not None):
            flag = "resume" if self.resume else "checkpoint_every"
            raise InvalidInput(
                f"{flag} needs a checkpoint directory: checkpoint_dir (--checkpoint-dir DIR)"
            )
        if self.wandb_project is not None:
            if not isinstance(self.wandb_project, str):
                raise InvalidInput(f"wandb_project must be a name, got {self.wandb_project!r}")
            from fppo_jax.store.metric_log import require_wandb

            require_wandb()

    @classmethod
    def flagged(cls) -> tuple[dataclasses.Field[Any], ...]:
        """The fields the command line sets with a flag of their own."""
        return tuple(f for f in dataclasses.fields(cls) if "help" in f.metadata)

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(field.name for field in dataclasses.fields(cls))

    @classmethod
    def split(cls, settings: Mapping[str, object]) -> tuple[Options, dict[str, object]]:
        """The options among a run's keyword `settings` (as given, unchecked), and the
        settings left."""
        names = cls.names()
        given = {name: value for name, value in settings.items() if name in names}
        # Options checks each value when made (__post_init__), whatever its type.
        options = cls(**given)  # type: ignore[arg-type]
        return options, {name: value for name, value in settings.items() if name not in names}
