"""fppo_jax.core.policy: a trained policy on its own: the most likely or a sampled action for raw
observations, normalised as in training, continuous actions clipped to their bounds."""

import functools
import json
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_bitwise_equal

from fppo_jax.core.distributions import Categorical
from fppo_jax.core.networks import make_networks
from fppo_jax.core.normalization import RunningStats
from fppo_jax.core.policy import Policy, make_policy
from fppo_jax.envs import Box, Discrete

BOX = Box((-1.0, -2.0), (1.0, 2.0))


def test_a_continuous_policy_round_trips_through_its_description():
    params = make_gaussian_params()
    stats = RunningStats(jnp.full(3, 0.5), jnp.full(3, 4.0), jnp.asarray(10.0))
    policy = Policy(params, stats, Box((-1.0, -2.0), (1.0, 2.0)), (8,))
    again = Policy.from_parts(policy.describe(), jax.device_get(policy.arrays()))
    obs = np.random.default_rng(0).normal(size=(16, 3)).astype(np.float32) * 5
    np.testing.assert_array_equal(again(obs), policy(obs))
    actions = np.asarray(again(obs, jax.random.key(0)))
    assert (np.abs(actions) <= [1.0, 2.0]).all()  # clipped to the bounds


def make_gaussian_params():
    from fppo_jax.core.networks import make_networks

    networks = make_networks(Box((-1.0, -2.0), (1.0, 2.0)), (8,))
    params = networks.init(jax.random.key(0), 3)["policy"]
    # Larger weights: wide means and standard deviations, so that sampled actions often reach
    # the bounds and are clipped.
    return jax.tree.map(lambda x: x * 50, params)


def gaussian_policy() -> Policy:
    stats = RunningStats(jnp.full(3, 0.5), jnp.full(3, 4.0), jnp.asarray(10.0))
    return Policy(make_gaussian_params(), stats, Box((-1.0, -2.0), (1.0, 2.0)), (8,))


def test_a_policy_refuses_a_non_finite_observation_saying_where():
    policy = gaussian_policy()
    obs = np.zeros((4, 3), np.float32)
    obs[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"holds nan at index \(2, 1\) \(1 non-finite"):
        policy(obs)
    assert policy(np.zeros(3)).shape == (2,)
    assert jax.jit(lambda o: policy(o))(jnp.zeros(3)).shape == (2,)  # inside jit: no check


@functools.partial(jax.jit, static_argnums=(0, 1))
def random_params(space, observation_size: int, seed: int) -> dict:
    """Policy parameters for `space` and (8,) hidden units, each standard normal (no orthogonal
    initialiser's QR to compile), so that actions differ from observation to observation."""
    network = make_networks(space, (8,)).policy
    obs = jnp.zeros(observation_size)
    shapes = jax.eval_shape(lambda k: network.init(k, obs), jax.random.key(0))
    leaves, tree = jax.tree.flatten(shapes)
    keys = jax.random.split(jax.random.key(seed), len(leaves))
    return tree.unflatten(
        [jax.random.normal(k, x.shape) for k, x in zip(keys, leaves, strict=True)]
    )


@functools.partial(jax.jit, static_argnums=0)
def distribution(space, params, obs):
    """The policy network's distribution for `obs`, straight from the network."""
    return make_networks(space, (8,)).policy.apply(params, obs)


def categorical_policy(stats: RunningStats | None) -> Policy:
    """Three actions from four observations."""
    return Policy(random_params(Discrete(3), 4, 1), stats, Discrete(3), (8,))


OBS = np.random.default_rng(0).normal(3.0, 4.0, size=(32, 4)).astype(np.float32)
STATS = RunningStats(jnp.full(4, 3.0), jnp.full(4, 16.0), jnp.asarray(100.0))


def test_the_most_likely_action_is_the_argmax_of_the_logits_of_the_normalised_observation():
    policy = categorical_policy(STATS)
    normalised = STATS.normalize(OBS)  # (x − μ) / sqrt(σ² + 1e-8), clipped to ±10
    logits = distribution(Discrete(3), policy.params, normalised).logits
    expected = np.argmax(np.asarray(logits), axis=-1)
    assert len(set(expected.tolist())) == 3  # every action is someone's most likely
    np.testing.assert_array_equal(policy(OBS), expected)
    # Statistics are applied once: the same network on raw observations acts otherwise.
    raw = categorical_policy(None)
    np.testing.assert_array_equal(raw(normalised), expected)
    assert not np.array_equal(raw(OBS), expected)


def test_a_sampled_action_is_the_distributions_sample_with_that_key():
    policy = categorical_policy(None)
    key = jax.random.key(7)
    logits = distribution(Discrete(3), policy.params, OBS).logits
    np.testing.assert_array_equal(policy(OBS, key), jax.jit(Categorical(logits).sample)(key))
    np.testing.assert_array_equal(policy(OBS, key), policy(OBS, key))  # a key, an action
    assert not np.array_equal(policy(OBS, jax.random.key(8)), policy(OBS, key))
    # Over many draws of one observation, each action as often as its probability.
    probabilities = np.exp(logits) / np.exp(logits).sum(-1, keepdims=True)
    i = int(np.argmax(probabilities.min(-1)))  # the observation most even between actions
    assert probabilities[i].min() > 0.05
    keys = jax.random.split(jax.random.key(0), 4000)
    drawn = np.asarray(jax.jit(jax.vmap(lambda k: policy.act(OBS[i], k)))(keys))
    frequencies = np.bincount(drawn, minlength=3) / len(drawn)
    np.testing.assert_allclose(frequencies, probabilities[i], atol=0.03)


def test_continuous_actions_are_the_mean_or_a_sample_clipped_to_the_bounds():
    policy = Policy(random_params(BOX, 3, 2), gaussian_policy().obs_stats, BOX, (8,))
    obs = np.random.default_rng(1).normal(size=(64, 3)).astype(np.float32) * 5
    normalised = policy.obs_stats.normalize(obs)
    dist = distribution(BOX, policy.params, normalised)
    low, high = np.array([-1.0, -2.0]), np.array([1.0, 2.0])
    mean = np.asarray(dist.mean)
    outside = (mean < low) | (mean > high)
    assert 0.1 < outside.mean() < 0.9  # clipping matters, and not everywhere
    np.testing.assert_allclose(policy(obs), np.clip(mean, low, high), rtol=1e-5, atol=1e-5)
    key = jax.random.key(3)
    sample = jax.jit(dist.sample)(key)
    np.testing.assert_allclose(
        policy(obs, key), np.clip(np.asarray(sample), low, high), rtol=1e-5, atol=1e-5
    )


def test_one_observation_or_a_batch():
    policy = categorical_policy(STATS)
    batch = np.asarray(policy(OBS))
    assert batch.shape == (32,) and batch.dtype == np.int32
    assert [int(policy(o)) for o in OBS[:4]] == batch[:4].tolist()
    assert policy(OBS[None]).shape == (1, 32)
    np.testing.assert_array_equal(jax.jit(policy.act)(OBS), batch)  # act: the same, pure
    assert policy.observation_size == 4 and gaussian_policy().observation_size == 3


def test_describe_is_json_ready_and_arrays_hold_the_statistics_only_when_normalising():
    assert categorical_policy(STATS).describe() == {
        "action_space": {"discrete": 3},
        "hidden_sizes": [8],
        "normalize_observations": True,
    }
    described = gaussian_policy().describe()
    assert described["action_space"] == {"low": [-1.0, -2.0], "high": [1.0, 2.0]}
    assert json.loads(json.dumps(described)) == described
    raw = categorical_policy(None)
    assert set(raw.arrays()) == {"params"} and raw.describe()["normalize_observations"] is False
    assert set(categorical_policy(STATS).arrays()["obs_stats"]) == {"mean", "var", "count"}
    again = Policy.from_parts(raw.describe(), jax.device_get(raw.arrays()))
    assert again.obs_stats is None and again.action_space == Discrete(3)
    assert_bitwise_equal(again.params, raw.params)


def test_make_policy_takes_the_states_policy_and_its_statistics_if_training_normalised():
    params = categorical_policy(None).params
    state = SimpleNamespace(params={"policy": params, "value": None}, obs_stats=STATS)
    for normalize in (True, False):
        config = SimpleNamespace(normalize_observations=normalize, hidden_sizes=(8,))
        trainer = SimpleNamespace(config=config, env=SimpleNamespace(action_space=Discrete(3)))
        policy = make_policy(trainer, state)
        assert policy.params is params and policy.hidden_sizes == (8,)
        assert policy.obs_stats is (STATS if normalize else None)
        assert policy.action_space == Discrete(3)
