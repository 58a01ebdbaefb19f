"""Gymnasium's API as an environment must keep it for :mod:`.gymnasium`: its spaces, and every
call to ``reset`` and ``step`` and every value they give, checked. A fault is an
``InvalidInput`` that names the environment and what it did wrong."""

from __future__ import annotations

import dataclasses
import math
import traceback
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from fppo_jax.envs.core import Box, Discrete
from fppo_jax.errors import InvalidInput, first_line

# What one environment's step gives as its reward, and as terminated and truncated, mostly.
SCALARS = (float, int, np.float32, np.float64, np.int64)
FLAGS = (bool, np.bool_)


@dataclasses.dataclass(frozen=True)
class CheckedApi:
    """Calls to one kind of environment, or of vector environment, whose values are checked
    against its spaces; `count` (a vector environment's sub-environments) is how many of each
    value a call gives, None for a ``gymnasium.Env``'s one."""

    name: str
    observation_size: int
    action_space: Discrete | Box
    action_start: int = 0  # a Discrete space's first action

    @classmethod
    def of(cls, gymnasium: Any, probe: Any, name: str) -> CheckedApi:
        """`probe`'s (an environment's or a vector environment's) spaces, refused where they
        are not a 1-D ``Box`` of observations and ``Discrete`` or 1-D ``Box`` actions."""
        if isinstance(probe, gymnasium.vector.VectorEnv):
            observations, actions = probe.single_observation_space, probe.single_action_space
            wrappers = "gymnasium.wrappers.vector.", "gymnasium.vector.VectorActionWrapper"
        else:
            observations, actions = probe.observation_space, probe.action_space
            wrappers = "gymnasium.wrappers.", "gymnasium.ActionWrapper"
        spaces = gymnasium.spaces
        if not isinstance(observations, spaces.Box) or len(observations.shape) != 1:
            raise InvalidInput(
                f"{name}: observations must be a 1-D Box, got {observations}; wrap the "
                f"environment in {wrappers[0]}FlattenObservation"
            )
        if observations.shape[0] == 0:
            raise InvalidInput(
                f"{name}: its observation space {observations} is empty, and a policy needs at "
                "least one number to act on"
            )
        size = int(observations.shape[0])
        if isinstance(actions, spaces.Discrete):
            return cls(name, size, Discrete(int(actions.n)), int(actions.start))
        if isinstance(actions, spaces.Box) and len(actions.shape) == 1:
            return cls(
                name, size, Box(tuple(map(float, actions.low)), tuple(map(float, actions.high)))
            )
        raise InvalidInput(
            f"{name}: actions must be Discrete or a 1-D Box, got {actions}; wrap the environment "
            f"in a {wrappers[1]} that maps one of those onto it"
        )

    def reset(self, env: Any, **arguments: Any) -> Any:
        """`env`'s first observation(s) from ``reset(**arguments)``, which must give
        (observation, info)."""
        expected = "the pair (observation, info) of Gymnasium's API"
        return self._called("reset", lambda: env.reset(**arguments), 2, expected)[0]

    def step(self, env: Any, action: Any) -> tuple[Any, ...]:
        """``env.step(action)``, which must give Gymnasium's five values."""
        expected = (
            "the five values (observation, reward, terminated, truncated, info) of Gymnasium's "
            "API (four are the old Gym API's, with one done for both terminated and truncated)"
        )
        return self._called("step", lambda: env.step(action), 5, expected)

    def _called(
        self, what: str, call: Callable[[], Any], size: int, expected: str
    ) -> tuple[Any, ...]:
        """`call`'s result, which must be a tuple of `size` values; what it raises, or returns
        otherwise, is an error naming the environment and `what` was called."""
        try:
            out = call()
        except Exception as error:
            raise InvalidInput(f"{self.name}: {what} {_raised(error)}") from error
        if not (isinstance(out, tuple) and len(out) == size):
            raise InvalidInput(f"{self.name}: {what} returned {_described(out)}, not {expected}")
        return out

    def check_step(self, out: tuple[Any, ...], count: int | None = None) -> None:
        """A step's outcome checked."""
        obs, reward, terminated, truncated, _ = out
        self.observation(obs, "step", count)
        self.reward(reward, count)
        self.flags(terminated, "terminated", count)
        self.flags(truncated, "truncated", count)

    def still_actions(self, count: int) -> np.ndarray:
        """`count` actions for a check, as Gymnasium takes them: a Discrete space's first, or
        the Box's point nearest zero."""
        width = 1 if isinstance(self.action_space, Discrete) else self.action_space.size
        return self.actions(np.zeros((count, width), np.float32))

    def actions(self, actions: np.ndarray) -> np.ndarray:
        """The actions [count, …] as Gymnasium takes them: a Discrete space's from its first
        action (integers, as its ``sample`` gives), a Box's clipped to its bounds."""
        if isinstance(self.action_space, Discrete):
            return cast(np.ndarray, actions[:, 0].astype(np.int64) + self.action_start)
        space = self.action_space
        return cast(np.ndarray, np.clip(actions, space.low, space.high).astype(np.float32))

    def reward(self, reward: Any, count: int | None = None) -> Any:
        """`reward` checked: one finite number, or `count` of them."""
        if count is None and type(reward) in SCALARS and math.isfinite(reward):
            return reward  # the usual case, at every step of every environment
        shape = () if count is None else (count,)
        values = _numbers(reward)
        if values is None or values.shape != shape or not np.isfinite(values).all():
            expected = "a finite number" if count is None else f"{count} finite numbers"
            raise InvalidInput(
                f"{self.name}: step returned the reward {_described(reward)}, not {expected}"
            )
        return values

    def flags(self, flags: Any, which: str, count: int | None = None) -> np.ndarray | bool:
        """`terminated` or `truncated` checked: one flag, or `count` of them."""
        if count is None and type(flags) in FLAGS:
            return bool(flags)  # the usual case, at every step of every environment
        shape = () if count is None else (count,)
        values = np.asarray(flags)
        if values.shape != shape or values.dtype.kind not in "biu":
            raise InvalidInput(
                f"{self.name}: step returned {which}={_described(flags)}, not "
                + ("a bool" if count is None else f"{count} bools")
            )
        return values.astype(bool)

    def observation(self, obs: Any, where: str, count: int | None = None) -> np.ndarray:
        """`obs` checked: one observation, or `count` of them. A copy, since a vector
        environment may hand back a buffer of its own that its reset rewrites."""
        checked = _numbers(obs)
        if checked is None:
            raise InvalidInput(
                f"{self.name}: {where} returned the observation {_described(obs)}, not numbers"
            )
        obs = checked.astype(np.float32)
        shape = (self.observation_size,) if count is None else (count, self.observation_size)
        if obs.shape != shape:
            raise InvalidInput(
                f"{self.name}: {where} returned observations of shape {obs.shape}, not {shape} "
                "as its observation space says"
            )
        if not np.isfinite(obs).all():
            raise InvalidInput(f"{self.name}: {where} returned a non-finite observation {obs}")
        return cast(np.ndarray, obs)  # `obs`, the parameter, is Any; it is `checked` now

    def final_observations(self, info: dict[str, Any], ended: np.ndarray) -> np.ndarray:
        """The final observations of the episodes that `ended`, from a SAME_STEP step's info."""
        if "final_obs" not in info:
            raise InvalidInput(
                f"{self.name}: its autoreset mode is SAME_STEP, but step gave no "
                "info['final_obs'] for the episodes that ended"
            )
        final = np.stack([info["final_obs"][i] for i in np.flatnonzero(ended)])
        return self.observation(final, "step's info['final_obs']", int(ended.sum()))


def _numbers(value: Any) -> np.ndarray | None:
    """`value` as an array of numbers (a copy), or None where it holds something else (None, a
    string, a ragged list)."""
    try:
        array = np.array(value)
    except (TypeError, ValueError):
        return None
    return array if array.dtype.kind in "biuf" else None


def _described(value: Any) -> str:
    """`value` in a few words, for an error: its type, and its shape or text."""
    if isinstance(value, tuple):
        return f"a {len(value)}-tuple"
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} ({value.dtype})"
    text = repr(value)
    return f"{text[:60]}…" if len(text) > 60 else f"{text} ({type(value).__name__})"


def _raised(error: Exception) -> str:
    """What an environment's own exception says, and where in its code it was raised."""
    frame = traceback.extract_tb(error.__traceback__)[-1]
    where = f"{frame.filename}:{frame.lineno}"
    return f"raised {type(error).__name__}: {first_line(error)} (at {where})"
