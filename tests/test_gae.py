import numpy as np

from fppo_jax.core.gae import gae


def gae_loop(rewards, values, next_values, terminated, truncated, gamma, lam):
    """The textbook recursion, one environment and one step at a time."""
    steps, envs = rewards.shape
    advantages = np.zeros((steps, envs))
    for e in range(envs):
        running = 0.0
        for t in reversed(range(steps)):
            bootstrap = 0.0 if terminated[t, e] else next_values[t, e]
            delta = rewards[t, e] + gamma * bootstrap - values[t, e]
            if terminated[t, e] or truncated[t, e]:
                running = 0.0
            running = delta + gamma * lam * running
            advantages[t, e] = running
    return advantages


def test_gae_with_truncation_matches_a_plain_loop():
    rng = np.random.default_rng(0)
    shape = (64, 5)
    rewards, values, next_values = (rng.normal(size=shape).astype(np.float32) for _ in range(3))
    terminated = rng.random(shape) < 0.05
    truncated = (rng.random(shape) < 0.05) & ~terminated
    terminated[10, 0] = truncated[10, 0] = True  # both at once: termination wins
    advantages, targets = gae(rewards, values, next_values, terminated, truncated, 0.99, 0.95)
    expected = gae_loop(rewards, values, next_values, terminated, truncated, 0.99, 0.95)
    np.testing.assert_allclose(advantages, expected, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(targets, expected + values, rtol=1e-4, atol=1e-5)


def test_truncation_bootstraps_and_termination_does_not():
    one = np.ones((1, 1), np.float32)
    args = (one, 0 * one, 10 * one)  # r = 1, V(s) = 0, V(s') = 10
    truncated, _ = gae(*args, np.array([[False]]), np.array([[True]]), 0.9, 0.95)
    terminated, _ = gae(*args, np.array([[True]]), np.array([[False]]), 0.9, 0.95)
    assert float(truncated[0, 0]) == np.float32(1 + 0.9 * 10)
    assert float(terminated[0, 0]) == 1.0
