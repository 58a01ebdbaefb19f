"""A tune's population, drawn through Optuna: per task one study of draws (a quasi-random or
random sampler over the shared axes and every arm's own), so that every arm gets the same points
on the axes they share, and per arm a study of its trials, which the rungs report their scores
to. Trial 0 is each arm's default (:func:`~fppo_jax.core.search_space.default_setting`)."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Mapping
from typing import Any, ParamSpec, TypeVar

from fppo_jax.analysis.tune_storage import study_name
from fppo_jax.core.search_space import (
    Interval,
    SearchSpace,
    default_setting,
)
from fppo_jax.core.shape_space import Choice
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.errors import MissingPackage, install_hint

P = ParamSpec("P")
R = TypeVar("R")


def import_optuna() -> Any:
    try:
        import optuna
    except ImportError:
        raise MissingPackage(f"tuning needs Optuna: {install_hint('tune')}") from None
    return optuna


def _defaults_kept(draw: Callable[P, R]) -> Callable[P, R]:
    """`draw` without Optuna's warning that an enqueued value lies outside its interval: trial
    0 is each arm's default, the baseline the report measures the others against, even where
    a space file's interval leaves it out (docs/tuning.md says so); it is never a draw."""

    @functools.wraps(draw)
    def quiet(*args: P.args, **kwargs: P.kwargs) -> R:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", r"Fixed parameter .* is out of range", UserWarning)
            return draw(*args, **kwargs)

    return quiet


@_defaults_kept
def draw_population(
    optuna: Any,
    storage: Any,
    task: str,
    arms: list[Surrogate],
    spaces: dict[str, SearchSpace],
    trials: int,
    sampler: str,
    seed: int,
) -> dict[str, list[dict[str, Any]]]:
    """Each arm's trials on `task`, as settings: trial 0 its default, the others drawn.

    The draws are one Optuna study (``draws``) over the shared axes and every arm's own
    (``<arm>.<name>``), so that the arms share their points on the shared axes; each draw is
    told ``PRUNED`` (drawn, not scored: Optuna's samplers learn a space from trials that
    ended). Each arm's trials are then a study of their own (named after the arm) that the
    rungs report their scores to; the studies' names carry the task and the tune's identity
    (:func:`~fppo_jax.analysis.tune_storage.study_name`). A study cut short while it was
    being drawn is drawn again from its seed: the same points."""
    draws = _draws(optuna, storage, task, arms, spaces, trials, sampler, seed)
    population = {}
    for arm in arms:
        axes = spaces[arm.name].axes
        name = study_name(storage, task, arm.name)
        study = _complete_study(optuna, storage, name, trials)
        if study is None:
            asked = optuna.create_study(direction="maximize")  # in memory, then stored at once
            for draw in draws:
                shared = {**spaces[arm.name].shared, **spaces[arm.name].shape}
                asked.enqueue_trial(
                    {
                        _param(k, axis): draw[_param(k if k in shared else f"{arm.name}.{k}", axis)]
                        for k, axis in axes.items()
                    }
                )
                trial = asked.ask()
                for key, axis in axes.items():
                    _suggest(trial, key, axis)
            study = _stored(optuna, storage, name, asked, direction="maximize")
        population[arm.name] = [
            dict(t.params) for t in sorted(study.get_trials(deepcopy=False), key=lambda t: t.number)
        ]
    return population


def _draws(
    optuna: Any,
    storage: Any,
    task: str,
    arms: list[Surrogate],
    spaces: dict[str, SearchSpace],
    trials: int,
    sampler: str,
    seed: int,
) -> list[dict[str, Any]]:
    first_space = next(iter(spaces.values()))
    axes: dict[str, Interval | Choice] = {**first_space.shared, **first_space.shape}
    defaults: dict[str, Any] = {k: default_setting(arms[0], task)[k] for k in first_space.shared}
    defaults |= first_space.shape_default
    for arm in arms:
        own = default_setting(arm, task)
        for key, interval in spaces[arm.name].own.items():
            axes[f"{arm.name}.{key}"] = interval
            defaults[f"{arm.name}.{key}"] = own[key]
    first = {_param(k, axis): _internal(defaults[k], axis) for k, axis in axes.items()}
    name = study_name(storage, task, "draws")
    study = _complete_study(optuna, storage, name, trials)
    if study is None:
        drawn = (
            # A run-shape axis is categorical: Sobol points cover the intervals, and its values
            # come from the sampler's own seeded random draws, which need no warning.
            optuna.samplers.QMCSampler(scramble=True, seed=seed, warn_independent_sampling=False)
            if sampler == "qmc"
            else optuna.samplers.RandomSampler(seed=seed)
        )
        drawing = optuna.create_study(sampler=drawn)  # in memory, then stored at once
        drawing.enqueue_trial(first)
        for _ in range(trials):
            trial = drawing.ask()
            for key, axis in axes.items():
                _suggest(trial, key, axis)
            drawing.tell(trial, state=optuna.trial.TrialState.PRUNED)
        study = _stored(optuna, storage, name, drawing)
        study.set_user_attr("role", "the points each arm's trials take; scores are in theirs")
    done = sorted(study.get_trials(deepcopy=False), key=lambda t: t.number)
    return [dict(t.params) for t in done]


def _stored(optuna: Any, storage: Any, name: str, made: Any, **direction: str) -> Any:
    """Study `name` in `storage`, holding the trials of `made` (a study in memory). Drawn there
    and stored trial by trial, the points are the same as drawn in `storage` itself, at a
    fraction of the cost: a database commits every parameter drawn in it on its own. Stored
    through the storage's own API, as drawn: trial 0, the default, may lie outside a space
    file's interval, which ``Study.add_trials`` would refuse."""
    study = optuna.create_study(study_name=name, storage=storage, **direction)
    study_id = storage.get_study_id_from_name(name)
    for trial in made.get_trials(deepcopy=False):
        storage.create_new_trial(study_id, template_trial=trial)
    return study


def _complete_study(optuna: Any, storage: Any, name: str, trials: int) -> Any:
    """Study `name`, if it holds its `trials` trials (each with its parameters); one cut short
    is deleted, to be made again."""
    try:
        study = optuna.load_study(study_name=name, storage=storage)
    except KeyError:
        return None
    held = study.get_trials(deepcopy=False)
    waiting = optuna.trial.TrialState.WAITING
    if len(held) == trials and all(t.state != waiting and t.params for t in held):
        return study
    optuna.delete_study(study_name=name, storage=storage)
    return None


def _param(name: str, axis: Interval | Choice) -> str:
    """What Optuna calls axis `name`: on a log1m scale it draws ``1-<name>``, log-uniformly."""
    return f"1-{name}" if isinstance(axis, Interval) and axis.scale == "log1m" else name


def _internal(value: Any, axis: Interval | Choice) -> Any:
    return 1 - value if isinstance(axis, Interval) and axis.scale == "log1m" else value


def _suggest(trial: Any, name: str, axis: Interval | Choice) -> None:
    """`trial`'s value of `name` on `axis`, drawn (or taken, if enqueued) and recorded."""
    if isinstance(axis, Choice):
        trial.suggest_categorical(name, list(axis.values))
    elif axis.scale == "log1m":
        trial.suggest_float(_param(name, axis), 1 - axis.high, 1 - axis.low, log=True)
    else:
        trial.suggest_float(name, axis.low, axis.high, log=axis.scale == "log")


def setting_of(params: Mapping[str, Any]) -> dict[str, Any]:
    """A trial's parameters as a setting (``1-gamma`` drawn is γ)."""
    return {
        (key[2:] if key.startswith("1-") else key): (1 - value if key.startswith("1-") else value)
        for key, value in params.items()
    }
