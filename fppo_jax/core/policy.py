"""A trained policy on its own: parameters, observation statistics and action space, with no
trainer and no environment, so that it can be saved, loaded and run anywhere."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, NotRequired, TypedDict, cast, final

import jax
import jax.numpy as jnp
import numpy as np
from flax.typing import VariableDict

from fppo_jax.core.networks import make_networks, policy_layers
from fppo_jax.core.normalization import RunningStats
from fppo_jax.core.trainer import Trainer, TrainState
from fppo_jax.envs import Box, Discrete
from fppo_jax.envs.core import key_shape
from fppo_jax.errors import InvalidInput

if TYPE_CHECKING:
    from fppo_jax.core.distributions import Distribution


@final  # so that a key tells the two apart
class DiscreteSpace(TypedDict):
    """A discrete action space as a policy's description records it: its number of actions."""

    discrete: int


@final
class BoxSpace(TypedDict):
    """A continuous action space as a policy's description records it: each action's bounds."""

    low: list[float]
    high: list[float]


class PolicyDescription(TypedDict):
    """A policy but its arrays, as saved policies and checkpoints record it (JSON): its action
    space, its network's hidden layer sizes and whether it normalises observations."""

    action_space: DiscreteSpace | BoxSpace
    hidden_sizes: list[int]
    normalize_observations: bool


class PolicyArrays(TypedDict):
    """A policy's arrays: its network's parameters and, where it normalises observations, their
    statistics (:class:`~fppo_jax.core.normalization.RunningStats`' fields, by name)."""

    params: VariableDict
    obs_stats: NotRequired[dict[str, jax.Array]]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Policy:
    """``policy(obs)`` is the most likely action for raw observations (one or a batch);
    ``policy(obs, key)`` samples. Observations are normalised with the statistics training
    ended with (when it normalised them); continuous actions are clipped to the action bounds,
    as in training. :meth:`act` is the same function, pure, to use inside ``jit``."""

    params: VariableDict  # the policy network's
    obs_stats: RunningStats | None  # None: observations are used raw
    action_space: Discrete | Box = dataclasses.field(metadata={"static": True})
    hidden_sizes: tuple[int, ...] = dataclasses.field(metadata={"static": True})

    @property
    def observation_size(self) -> int:
        """The size of the observations the policy takes (its first layer's inputs)."""
        return int(policy_layers(self.params)[0]["kernel"].shape[-2])

    def act(self, obs: jax.Array, key: jax.Array | None = None) -> jax.Array:
        obs = jnp.asarray(obs, jnp.float32)
        if obs.shape[-1:] != (self.observation_size,):
            raise InvalidInput(
                f"the policy takes observations of size {self.observation_size} (the last "
                f"axis), got shape {obs.shape}"
            )
        if self.obs_stats is not None:
            obs = self.obs_stats.normalize(obs)
        networks = make_networks(self.action_space, self.hidden_sizes)
        dist = cast("Distribution", networks.policy.apply(self.params, obs))
        action = dist.mode() if key is None else dist.sample(key)
        if isinstance(self.action_space, Box):
            action = jnp.clip(
                action, jnp.asarray(self.action_space.low), jnp.asarray(self.action_space.high)
            )
        return action

    def __call__(self, obs: jax.Array, key: jax.Array | None = None) -> jax.Array:
        """:meth:`act`, compiled; a concrete observation holding NaN or infinity is refused,
        since no action follows from it (:meth:`act` itself stays pure, for ``jit``)."""
        if not isinstance(obs, jax.core.Tracer):
            values = np.asarray(obs, np.float32)
            bad = np.argwhere(~np.isfinite(values))
            if bad.size:
                raise InvalidInput(
                    f"the observation holds {values[tuple(bad[0])]} at index "
                    f"{tuple(int(i) for i in bad[0])} ({len(bad)} non-finite values in all): "
                    "no action follows from it"
                )
        return cast(jax.Array, _act(self, obs, key))

    def describe(self) -> PolicyDescription:
        """Everything but the arrays, as JSON-ready values (see :meth:`from_parts`)."""
        space = self.action_space
        return {
            "action_space": DiscreteSpace(discrete=space.n)
            if isinstance(space, Discrete)
            else BoxSpace(low=list(space.low), high=list(space.high)),
            "hidden_sizes": list(self.hidden_sizes),
            "normalize_observations": self.obs_stats is not None,
        }

    def arrays(self) -> PolicyArrays:
        """The arrays (see :meth:`from_parts`)."""
        arrays = PolicyArrays(params=self.params)
        if self.obs_stats is not None:
            arrays["obs_stats"] = dataclasses.asdict(self.obs_stats)
        return arrays

    @classmethod
    def from_parts(cls, description: PolicyDescription, arrays: PolicyArrays) -> Policy:
        """The policy that :meth:`describe` and :meth:`arrays` describe."""
        space = description["action_space"]
        action_space = (
            Discrete(int(space["discrete"]))
            if "discrete" in space
            else Box(tuple(map(float, space["low"])), tuple(map(float, space["high"])))
        )
        stats = None
        if description["normalize_observations"]:
            stats = RunningStats(**{k: jnp.asarray(v) for k, v in arrays["obs_stats"].items()})
        params = jax.tree.map(lambda x: jnp.asarray(np.asarray(x)), arrays["params"])
        policy = cls(params, stats, action_space, tuple(description["hidden_sizes"]))
        policy._check_shapes()
        return policy

    def _check_shapes(self) -> None:
        """Raise InvalidInput unless the parameters are those of the network the action space and
        hidden sizes make (a description edited apart from its arrays, say)."""
        networks = make_networks(self.action_space, self.hidden_sizes)
        obs = jax.ShapeDtypeStruct((self.observation_size,), jnp.float32)
        expected = jax.eval_shape(networks.policy.init, key_shape(), obs)
        shapes = {
            jax.tree_util.keystr(path): tuple(leaf.shape)
            for path, leaf in jax.tree_util.tree_leaves_with_path(expected)
        }
        found = {
            jax.tree_util.keystr(path): tuple(np.shape(leaf))
            for path, leaf in jax.tree_util.tree_leaves_with_path(self.params)
        }
        if shapes != found:
            where = sorted(set(shapes) ^ set(found)) or [k for k in shapes if shapes[k] != found[k]]
            name = where[0]
            raise InvalidInput(
                f"its arrays are not those of a {list(self.hidden_sizes)} network for its action "
                f"space: {name} is {found.get(name, 'missing')}, expected "
                f"{shapes.get(name, 'none')}"
            )


_act = jax.jit(Policy.act)


def make_policy(trainer: Trainer, state: TrainState) -> Policy:
    """The policy of `state` (batched along runs if the state is), on its own."""
    config = trainer.config
    return Policy(
        params=state.params["policy"],
        obs_stats=state.obs_stats if config.normalize_observations else None,
        action_space=trainer.env.action_space,
        hidden_sizes=config.hidden_sizes,
    )
