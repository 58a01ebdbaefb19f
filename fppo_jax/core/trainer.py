"""The training program: ``make_train(config, env)`` returns a pure ``train_fn(key, hp)``.

One update is: a rollout (:mod:`fppo_jax.core.rollout`: ``lax.scan`` over steps, environments
vmapped and auto-reset), GAE, then epochs × shuffled minibatches of the variant's loss. The
whole run is one loop of updates, so ``jax.jit(train_fn)`` compiles it once and ``jax.vmap``
over keys and :class:`Hyperparameters` trains seeds and settings side by side.
:meth:`Trainer.run` runs a chunk of updates from a state, for progress reporting between
compiled calls.

Each part of an update runs under a ``jax.named_scope`` (``rollout``, ``advantages``,
``epochs`` with ``shuffle``, ``minibatches``, ``gradient`` and ``optimizer`` inside, then
``escape``), so that a profile names the part each compiled operation belongs to.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp
import optax

from fppo_jax.core.config import Hyperparameters, TrainConfig, run_length
from fppo_jax.core.gae import gae
from fppo_jax.core.losses import Batch, LossInfo, ppo_loss
from fppo_jax.core.networks import Networks, Params, make_networks
from fppo_jax.core.normalization import RunningStats
from fppo_jax.core.objectives import Objective
from fppo_jax.core.permutation import permutation
from fppo_jax.core.rollout import Envs, Transition, rollout
from fppo_jax.core.variants import distance_past_bound, negative_regions
from fppo_jax.envs import (
    Environment,
    check_environment,
)

RETURN_WINDOW = 100  # episodes in `average_return` (the paper's average return)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrainState:
    """Everything a run carries from one update to the next."""

    params: Params
    opt_state: optax.OptState
    obs_stats: RunningStats
    return_stats: RunningStats
    envs: Envs
    recent_returns: jax.Array  # ring buffer of the last RETURN_WINDOW finished episodes
    num_episodes: jax.Array
    update: jax.Array
    nonfinite_update: jax.Array  # first update whose loss or parameters were not finite, or -1
    key: jax.Array


# Loss diagnostics averaged over the first epoch only, and their metrics' names. The escape
# speed: the fraction of the batch in R+ ∪ R- as each minibatch meets it before training on it.
_FIRST_EPOCH = {"negative_fraction": "negative_fraction_before"}


class Metrics(NamedTuple):
    """One row per update."""

    env_steps: jax.Array
    average_return: jax.Array  # mean return of the last 100 finished episodes (NaN before any)
    # LossInfo's diagnostics, averaged over the update (the first epoch's, where renamed).
    policy_loss: jax.Array
    value_loss: jax.Array
    entropy: jax.Array
    approx_kl: jax.Array
    clip_fraction: jax.Array
    negative_fraction_before: jax.Array
    # The escape speed, under the parameters after the last epoch: the fraction of the batch in
    # R+ ∪ R-, and how far past the bound those samples sit on average.
    negative_fraction_after: jax.Array
    negative_distance_after: jax.Array


METRICS: tuple[str, ...] = Metrics._fields


class Collected(NamedTuple):
    """A rollout and what follows from it: the update's batch (advantages and targets
    included), the trajectory, the environments where it left them, and the normalisers'
    statistics with its samples."""

    batch: Batch
    trajectory: Transition
    envs: Envs
    obs_stats: RunningStats
    return_stats: RunningStats


class Trained(NamedTuple):
    """What an update's epochs leave: the parameters and the optimiser's state, each
    minibatch step's loss and diagnostics [epoch, minibatch], and (when tracked) the fraction
    of the batch in R+ ∪ R- after each epoch."""

    params: Any
    opt_state: Any
    losses: jax.Array
    infos: LossInfo
    escape_by_epoch: jax.Array | None


def make_optimizer(hp: Hyperparameters, config: TrainConfig) -> optax.GradientTransformation:
    """Global-norm clipping then Adam (ε = 1e-5), one optimiser for policy and value.

    It runs on the parameters flattened into one vector: a handful of kernels per step instead
    of several per parameter array, which is most of a small network's optimiser cost.
    """
    learning_rate: Any = hp.learning_rate
    if config.anneal_learning_rate:
        steps_per_update = config.num_epochs * config.num_minibatches
        num_updates = run_length(hp, config)

        def learning_rate(count: jax.Array) -> jax.Array:
            return hp.learning_rate * (1.0 - (count // steps_per_update) / num_updates)

    return optax.flatten(
        optax.chain(
            optax.clip_by_global_norm(hp.max_grad_norm), optax.adam(learning_rate, eps=1e-5)
        )
    )


def _push_returns(
    recent: jax.Array, num_episodes: jax.Array, done: jax.Array, returns: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Append the returns of finished episodes (time-major order) to the ring buffer."""
    done, returns = done.reshape(-1), returns.reshape(-1)
    rank = jnp.cumsum(done)
    finished = rank[-1]
    # Only the newest RETURN_WINDOW of this rollout, so that no two writes share a slot.
    keep = done & (rank > finished - RETURN_WINDOW)
    slot = jnp.where(keep, (num_episodes + rank - 1) % RETURN_WINDOW, RETURN_WINDOW)
    return recent.at[slot].set(returns, mode="drop"), num_episodes + finished


def _keep_if_finite(new: TrainState, old: TrainState, losses: jax.Array) -> TrainState:
    """`new`; but if a loss or a parameter is not finite, `old`, with the update counted and the
    first such update recorded."""
    finite = jnp.all(jnp.isfinite(losses)) & jnp.all(
        jnp.stack([jnp.all(jnp.isfinite(p)) for p in jax.tree.leaves(new.params)])
    )
    kept: TrainState = jax.tree.map(lambda n, o: jnp.where(finite, n, o), new, old)
    first_bad = jnp.where((old.nonfinite_update < 0) & ~finite, old.update, old.nonfinite_update)
    return dataclasses.replace(kept, update=new.update, nonfinite_update=first_bad)


def _loss_metrics(infos: LossInfo) -> dict[str, jax.Array]:
    """The update's loss diagnostics, [epoch, minibatch] each, averaged, by metric name."""
    return {
        _FIRST_EPOCH.get(name, name): jnp.mean(value[0] if name in _FIRST_EPOCH else value)
        for name, value in infos._asdict().items()
    }


def _average_return(recent: jax.Array, num_episodes: jax.Array) -> jax.Array:
    filled = jnp.minimum(num_episodes, RETURN_WINDOW)
    total = jnp.sum(jnp.where(jnp.arange(RETURN_WINDOW) < filled, recent, 0.0))
    return jnp.where(filled > 0, total / jnp.maximum(filled, 1), jnp.nan)


@dataclasses.dataclass(frozen=True)
class Trainer:
    """``trainer(key, hp)`` trains a whole run; ``init`` and ``run`` train it in chunks."""

    config: TrainConfig
    env: Environment
    networks: Networks

    def __call__(self, key: jax.Array, hp: Hyperparameters) -> tuple[TrainState, Metrics]:
        return self.run(self.init(key, hp), hp, self.config.num_updates)

    def init(self, key: jax.Array, hp: Hyperparameters) -> TrainState:
        config, env = self.config, self.env
        key, net_key, env_key = jax.random.split(key, 3)
        params = self.networks.init(net_key, env.observation_size)
        return TrainState(
            params=params,
            opt_state=make_optimizer(hp, config).init(params),
            obs_stats=RunningStats.create((env.observation_size,)),
            return_stats=RunningStats.create(),
            envs=self._fresh_envs(env_key),
            recent_returns=jnp.zeros(RETURN_WINDOW),
            num_episodes=jnp.asarray(0, jnp.int32),
            update=jnp.asarray(0, jnp.int32),
            nonfinite_update=jnp.asarray(-1, jnp.int32),
            key=key,
        )

    def restart_envs(self, state: TrainState) -> TrainState:
        """`state` with every environment starting a new episode, drawn from the run's key and
        update: for a restored run whose environments' state lived outside JAX (see
        :func:`~fppo_jax.envs.core.resets_itself`), which no checkpoint holds. Episodes in
        progress are dropped; everything learnt, the normalisers included, is kept."""
        key = jax.random.fold_in(state.key, state.update)
        return dataclasses.replace(state, envs=self._fresh_envs(key))

    def _fresh_envs(self, key: jax.Array) -> Envs:
        num_envs = self.config.num_envs
        env_state, obs = jax.vmap(self.env.reset)(jax.random.split(key, num_envs))
        zeros = jnp.zeros(num_envs)
        return Envs(env_state, obs, episode_return=zeros, discounted_return=zeros)

    def run(
        self, state: TrainState, hp: Hyperparameters, num_updates: int
    ) -> tuple[TrainState, Metrics]:
        """`num_updates` updates from `state`, fewer where the run ends first: the rows of
        updates past its end are NaN (``env_steps`` -1), so equal chunks reuse one compiled
        program."""
        nan = jnp.asarray(jnp.nan, jnp.float32)
        past_end = Metrics(jnp.asarray(-1, jnp.int32), *[nan] * (len(METRICS) - 1))
        rows = jax.tree.map(lambda x: jnp.full((num_updates, *x.shape), x), past_end)

        # A loop of as many updates as are left, not a `cond` in a loop of `num_updates`: XLA's
        # CPU runtime ran an MJX update inside a conditional 11% slower (Hopper, 128 envs).
        def step(i: jax.Array, carry: tuple[TrainState, Metrics]) -> tuple[TrainState, Metrics]:
            state, rows = carry
            state, metrics = self.update(state, hp)
            return state, jax.tree.map(lambda all_rows, row: all_rows.at[i].set(row), rows, metrics)

        left = jnp.clip(run_length(hp, self.config) - state.update, 0, num_updates)
        return cast("tuple[TrainState, Metrics]", jax.lax.fori_loop(0, left, step, (state, rows)))

    def update(self, state: TrainState, hp: Hyperparameters) -> tuple[TrainState, Metrics]:
        """One rollout and one PPO update; a non-finite result keeps the state it started from."""
        config = self.config
        key, rollout_key, epochs_key = jax.random.split(state.key, 3)
        batch, traj, envs, obs_stats, return_stats = self.collect(state, hp, rollout_key)
        with jax.named_scope("epochs"):
            params, opt_state, losses, infos, _ = self._epochs(state, hp, batch, epochs_key)
        with jax.named_scope("escape"):
            negative_fraction, negative_distance = self._escape(params, batch, hp.objective)

        done = traj.terminated | traj.truncated
        recent_returns, num_episodes = _push_returns(
            state.recent_returns, state.num_episodes, done, traj.episode_return
        )
        new_state = dataclasses.replace(
            state,
            params=params,
            opt_state=opt_state,
            obs_stats=obs_stats,
            return_stats=return_stats,
            envs=envs,
            recent_returns=recent_returns,
            num_episodes=num_episodes,
            update=state.update + 1,
            key=key,
        )
        metrics = Metrics(
            env_steps=(new_state.update * config.samples_per_update).astype(jnp.int32),
            average_return=_average_return(recent_returns, num_episodes),
            **_loss_metrics(infos),
            negative_fraction_after=negative_fraction,
            negative_distance_after=negative_distance,
        )
        return _keep_if_finite(new_state, state, losses), metrics

    def collect(self, state: TrainState, hp: Hyperparameters, key: jax.Array) -> Collected:
        """A rollout and its batch (advantages, targets), with the environments where the
        rollout left them and the updated normaliser statistics."""
        config = self.config
        with jax.named_scope("rollout"):
            traj, envs = self._rollout(state, hp, key)
        obs_stats, return_stats = state.obs_stats, state.return_stats
        if config.normalize_observations:
            obs_stats = obs_stats.update(traj.raw_obs)
        rewards = traj.reward
        if config.normalize_rewards:
            return_stats = return_stats.update(traj.discounted_return)
            rewards = return_stats.scale(rewards)

        # The value to bootstrap from is always that of the observation a step produced, before
        # any reset: V(obs_{t+1}) mid-episode, V(last state) at truncation, and 0 at termination.
        # Computing every value here in one batch keeps the critic out of the sequential rollout.
        with jax.named_scope("advantages"):
            final_obs = self.network_input(state.obs_stats, traj.final_obs)
            values, next_values = jnp.split(
                self.networks.values(state.params, jnp.concatenate([traj.obs, final_obs])), 2
            )
            advantages, targets = gae(
                rewards,
                values,
                next_values,
                traj.terminated,
                traj.truncated,
                hp.gamma,
                hp.gae_lambda,
            )
            # Normalised over the whole batch (baselines does it per minibatch) so that each
            # sample's sign, and so its region R+ or R-, is fixed for the update.
            advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)

        flat = lambda x: x.reshape((config.samples_per_update, *x.shape[2:]))  # noqa: E731
        batch = jax.tree.map(
            flat,
            Batch(
                traj.obs, traj.action, traj.log_prob, values, advantages, targets, traj.distribution
            ),
        )
        return Collected(batch, traj, envs, obs_stats, return_stats)

    def escape_by_epoch(
        self, state: TrainState, hp: Hyperparameters, batch: Batch | None = None
    ) -> jax.Array:
        """The escape speed of the next update from `state`: the fraction of its batch in R+ ∪ R-
        after each of its epochs, [num_epochs] (before the first, every ratio is 1 and none is).
        The batch and the minibatch order are those :meth:`update` would use, so variants
        given the same state are compared on the same samples. Environments stepped outside
        JAX (native MuJoCo) give a new batch at every rollout: collect it once
        (:meth:`collect`) and pass it as `batch` to compare variants on it."""
        _, rollout_key, epochs_key = jax.random.split(state.key, 3)
        if batch is None:
            batch = self.collect(state, hp, rollout_key).batch
        return cast(  # not None: track_escape
            jax.Array, self._epochs(state, hp, batch, epochs_key, track_escape=True).escape_by_epoch
        )

    def network_input(self, stats: RunningStats, obs: jax.Array) -> jax.Array:
        """Raw observations as the networks see them (normalised with `stats` if configured)."""
        return stats.normalize(obs) if self.config.normalize_observations else obs

    def _escape(
        self, params: Params, batch: Batch, objective: Objective
    ) -> tuple[jax.Array, jax.Array]:
        """The fraction of the batch in R+ ∪ R- under `params`, and how far past the bound those
        samples sit on average (the escape speed's measures), by the surrogate's clip range."""
        dist = self.networks.distribution(params, batch.obs)
        ratio = jnp.exp(dist.log_prob(batch.action) - batch.log_prob)
        below, above = objective.clip_range()
        r_plus, r_minus = negative_regions(ratio, batch.advantage, below, above)
        negative = r_plus | r_minus
        distance = jnp.sum(jnp.where(negative, distance_past_bound(ratio, below, above), 0.0))
        return jnp.mean(negative), distance / jnp.maximum(jnp.sum(negative), 1)

    def _rollout(
        self, state: TrainState, hp: Hyperparameters, key: jax.Array
    ) -> tuple[Transition, Envs]:
        """A rollout from `state` (:func:`~fppo_jax.core.rollout.rollout`)."""
        observe = functools.partial(self.network_input, state.obs_stats)
        return rollout(
            self.config, self.env, self.networks, state.params, observe, state.envs, hp, key
        )

    def _epochs(
        self,
        state: TrainState,
        hp: Hyperparameters,
        batch: Batch,
        key: jax.Array,
        track_escape: bool = False,
    ) -> Trained:
        """Epochs × shuffled minibatches, tracking the escape speed by epoch if asked."""
        config = self.config
        optimizer = make_optimizer(hp, config)
        value_and_grad = jax.value_and_grad(ppo_loss, has_aux=True)

        def minibatch_step(
            carry: tuple[Any, Any], minibatch: Batch
        ) -> tuple[tuple[Any, Any], tuple[Any, ...]]:  # (loss, info)
            params, opt_state = carry
            with jax.named_scope("gradient"):
                (loss, info), grads = value_and_grad(
                    params, minibatch, hp, self.networks, config.clip_value_loss
                )
            with jax.named_scope("optimizer"):
                updates, opt_state = optimizer.update(grads, opt_state, params)
                params = optax.apply_updates(params, updates)
            return (params, opt_state), (loss, info)

        def epoch(
            carry: tuple[Any, Any], order: jax.Array
        ) -> tuple[tuple[Any, Any], tuple[Any, ...]]:
            shape = (config.num_minibatches, config.minibatch_size)
            with jax.named_scope("minibatches"):
                minibatches = jax.tree.map(lambda x: x[order].reshape(shape + x.shape[1:]), batch)
            carry, out = jax.lax.scan(minibatch_step, carry, minibatches)
            if track_escape:
                out = (*out, self._escape(carry[0], batch, hp.objective)[0])
            return carry, out

        # Every epoch's shuffle in one batched draw, outside the loop.
        keys = jax.random.split(key, config.num_epochs)
        with jax.named_scope("shuffle"):
            orders = jax.vmap(permutation, (0, None))(keys, config.samples_per_update)
        carry = (state.params, state.opt_state)
        (params, opt_state), (losses, infos, *escape) = jax.lax.scan(epoch, carry, orders)
        return Trained(params, opt_state, losses, infos, escape[0] if escape else None)


def make_train(config: TrainConfig, env: Environment) -> Trainer:
    """The training program for `config` on `env`: a pure function of (key, hyperparameters).
    `env` is checked against the interface first (:func:`~fppo_jax.envs.core.check_environment`),
    so that a broken one is named here rather than deep in a trace."""
    check_environment(env)
    return Trainer(
        config, env, make_networks(env.action_space, config.hidden_sizes, config.initial_log_std)
    )
