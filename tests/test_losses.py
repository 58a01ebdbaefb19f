"""fppo_jax.core.losses: the PPO-family loss of a minibatch, term by term, against a direct
computation from its definition."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax.core.distributions import Categorical
from fppo_jax.core.losses import Batch
from fppo_jax.core.losses import ppo_loss as eager_ppo_loss
from fppo_jax.core.networks import make_networks
from fppo_jax.core.resolution import hyperparameters
from fppo_jax.envs import Discrete

N = 64
# Compiled whole: many times faster than op by op.
ppo_loss = jax.jit(eager_ppo_loss, static_argnums=(3, 4))


def discrete_case(seed: int = 0):
    """Networks, their parameters, and a minibatch whose rollout policy was another one, so that
    the ratios spread on both sides of the clip range; the old values differ from the network's
    by up to 1, the targets from the old values by a standard normal."""
    networks = make_networks(Discrete(3), (16,))
    return (networks, *_discrete_case(networks, seed))


def random_params(networks, observation_size: int, key):
    """Parameters of the networks' shapes, each standard normal (no orthogonal initialiser's
    QR to compile)."""
    shapes = jax.eval_shape(lambda k: networks.init(k, observation_size), jax.random.key(0))
    leaves, tree = jax.tree.flatten(shapes)
    keys = jax.random.split(key, len(leaves))
    return tree.unflatten(
        [jax.random.normal(k, x.shape) for k, x in zip(keys, leaves, strict=True)]
    )


@functools.partial(jax.jit, static_argnums=0)
def _discrete_case(networks, seed):
    keys = jax.random.split(jax.random.key(seed), 8)
    params = random_params(networks, 4, keys[0])
    obs = jax.random.normal(keys[1], (N, 4))
    old = Categorical(
        networks.distribution(params, obs).logits + jax.random.normal(keys[2], (N, 3))
    )
    action = old.sample(keys[3])
    value = networks.values(params, obs) + jax.random.uniform(keys[4], (N,), minval=-1, maxval=1)
    batch = Batch(
        obs=obs,
        action=action,
        log_prob=old.log_prob(action),
        value=value,
        advantage=jax.random.normal(keys[5], (N,)),
        target=value + jax.random.normal(keys[6], (N,)),
        distribution=old,
    )
    return params, batch


def expected_terms(networks, params, batch, epsilon: float, clip_value_loss: bool) -> dict:
    """Each term from its definition, in float64."""
    logits = np.asarray(networks.distribution(params, batch.obs).logits, np.float64)
    log_p = logits - np.log(np.exp(logits).sum(-1, keepdims=True))
    new_log_prob = log_p[np.arange(N), np.asarray(batch.action)]
    ratio = np.exp(new_log_prob - np.asarray(batch.log_prob, np.float64))
    a = np.asarray(batch.advantage, np.float64)
    lo, hi = 1 - epsilon, 1 + epsilon
    v = np.asarray(networks.values(params, batch.obs), np.float64)
    v_old, target = np.asarray(batch.value, np.float64), np.asarray(batch.target, np.float64)
    error = (v - target) ** 2
    if clip_value_loss:
        error = np.maximum(error, (v_old + np.clip(v - v_old, -epsilon, epsilon) - target) ** 2)
    return {
        "ratio": ratio,
        "policy_loss": -np.mean(np.minimum(ratio * a, np.clip(ratio, lo, hi) * a)),
        "value_loss": 0.5 * np.mean(error),
        "entropy": np.mean(-(np.exp(log_p) * log_p).sum(-1)),
        "approx_kl": np.mean((ratio - 1) - np.log(ratio)),
        "clip_fraction": np.mean(np.abs(ratio - 1) > epsilon),
        "negative_fraction": np.mean(((a > 0) & (ratio < lo)) | ((a < 0) & (ratio > hi))),
    }


@pytest.mark.parametrize("clip_value_loss", [True, False])
def test_the_ppo_loss_and_its_diagnostics_follow_their_definitions(clip_value_loss):
    networks, params, batch = discrete_case()
    hp = hyperparameters("ppo", value_coef=0.7, entropy_coef=0.05)
    loss, info = ppo_loss(params, batch, hp, networks, clip_value_loss)
    expected = expected_terms(networks, params, batch, 0.2, clip_value_loss)
    ratio = expected["ratio"]
    # The case reaches both sides of the clip range and both negatively optimised regions.
    assert (ratio < 0.8).mean() > 0.1 and (ratio > 1.2).mean() > 0.1
    assert 0 < expected["negative_fraction"] < 1
    for name in ("policy_loss", "value_loss", "entropy", "approx_kl"):
        assert float(getattr(info, name)) == pytest.approx(expected[name], rel=1e-4), name
    for name in ("clip_fraction", "negative_fraction"):  # counts: exact
        assert float(getattr(info, name)) == pytest.approx(expected[name], abs=1e-6), name
    total = expected["policy_loss"] + 0.7 * expected["value_loss"] - 0.05 * expected["entropy"]
    assert float(loss) == pytest.approx(total, rel=1e-4)


def test_value_clipping_keeps_the_larger_error_within_epsilon_of_the_old_value():
    networks, params, batch = discrete_case(1)
    hp = hyperparameters("ppo")
    clipped = float(ppo_loss(params, batch, hp, networks, True)[1].value_loss)
    plain = float(ppo_loss(params, batch, hp, networks, False)[1].value_loss)
    assert clipped > plain  # the clipped error counts where it is the larger
    # New values within ε of the old: clipping changes nothing.
    near = batch._replace(value=networks.values(params, batch.obs) + 0.1)
    assert float(ppo_loss(params, near, hp, networks, True)[1].value_loss) == pytest.approx(
        float(ppo_loss(params, near, hp, networks, False)[1].value_loss), rel=1e-6
    )
    # Values far from the old and from the target: ½ mean max((V − R)², (V_old ± ε − R)²).
    v = networks.values(params, batch.obs)
    far = batch._replace(value=v - 5, target=v - 2)
    value_loss = float(ppo_loss(params, far, hp, networks, True)[1].value_loss)
    assert value_loss == pytest.approx(0.5 * (5 - 0.2 - 2) ** 2, rel=1e-5)  # (2.8)² beats 2²
    assert float(ppo_loss(params, far, hp, networks, False)[1].value_loss) == pytest.approx(2.0)


def test_the_diagnostics_carry_no_gradient():
    networks, params, batch = discrete_case(2)
    hp = hyperparameters("fppo-qp", entropy_coef=0.01)

    def diagnostics(p):
        info = ppo_loss(p, batch, hp, networks, True)[1]
        return info.policy_loss + info.value_loss + info.approx_kl + info.entropy

    grads = jax.grad(diagnostics)(params)  # only the loss itself is to be differentiated
    assert all(float(jnp.abs(g).max()) == 0 for g in jax.tree.leaves(grads))
