import flax.linen as nn
import jax
import numpy as np

from fppo_jax.core.networks import make_networks, orthogonal, policy_layers
from fppo_jax.envs import Box, Discrete


def test_orthogonal_matches_flax_and_stays_unbatched_under_vmap():
    init = orthogonal(1.0)
    key = jax.random.key(0)
    np.testing.assert_array_equal(
        init(key, (64, 64)), nn.initializers.orthogonal(1.0)(key, (64, 64))
    )
    keys = jax.random.split(key, 3)
    batched = jax.vmap(lambda k: init(k, (8, 8)))(keys)
    np.testing.assert_array_equal(batched[2], init(keys[2], (8, 8)))
    # A batched QR deadlocked jaxlib's CPU thread pool: under vmap, each QR is of one matrix.
    hlo = jax.jit(jax.vmap(lambda k: init(k, (8, 8)))).lower(keys).as_text()
    qr_calls = [line for line in hlo.splitlines() if "geqrf" in line and "custom_call" in line]
    assert qr_calls and all("tensor<8x8xf32>" in line and "3x8x8" not in line for line in qr_calls)


def test_policies_for_each_action_space():
    obs = np.zeros((5, 3), np.float32)
    discrete = make_networks(Discrete(4), (16,))
    params = discrete.init(jax.random.key(0), 3)
    assert discrete.distribution(params, obs).logits.shape == (5, 4)
    assert discrete.values(params, obs).shape == (5,)
    gaussian = make_networks(Box((-1.0, -1.0), (1.0, 1.0)), (16,))
    params = gaussian.init(jax.random.key(0), 3)
    dist = gaussian.distribution(params, obs)
    assert dist.mean.shape == (5, 2) and np.all(np.asarray(dist.log_std) == 0.0)
    assert gaussian.action_noise(jax.random.key(1), (7, 5)).shape == (7, 5, 2)


def test_the_policy_s_layers_in_order_for_each_action_space():
    for space, outputs in ((Discrete(4), 4), (Box((-1.0,) * 2, (1.0,) * 2), 2)):
        params = make_networks(space, (16, 8)).init(jax.random.key(0), 3)["policy"]
        layers = policy_layers(params)
        assert [layer["kernel"].shape for layer in layers] == [(3, 16), (16, 8), (8, outputs)]
        assert [layer["bias"].shape for layer in layers] == [(16,), (8,), (outputs,)]
