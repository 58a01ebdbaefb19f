"""fppo_jax.run.evaluation: the undiscounted return of whole episodes, run side by side, and the
command line's report of it."""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fppo_jax
from fppo_jax import train
from fppo_jax.cli import main
from fppo_jax.core.networks import make_networks
from fppo_jax.core.policy import Policy
from fppo_jax.envs import Discrete, Step
from fppo_jax.errors import InvalidInput
from fppo_jax.run.evaluation import evaluate, evaluation_key, make_evaluator

TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
RUN = {"env": "cartpole", "variant": "fppo-qp", "seed": 3, "total_steps": 128 * 20, **TINY}


def test_eval_reports_deterministic_and_stochastic_returns(tmp_path, capsys):
    train(**RUN, checkpoint_dir=tmp_path)
    assert main(["eval", "--checkpoint", str(tmp_path), "--episodes", "4"]) == 0
    out = capsys.readouterr().out
    assert "fppo-qp on cartpole, seed 3: checkpoint at update 20 (2,560 env steps)" in out
    assert "(2,560 env steps); 4 episodes each\n" in out
    env, policy = fppo_jax.make_env("cartpole"), fppo_jax.load_policy(tmp_path)
    for line, deterministic in (("deterministic return", True), ("stochastic    return", False)):
        text = next(x for x in out.splitlines() if line in x)
        mean, spread = (float(x) for x in text.split("return")[1].split("(")[0].split("±"))
        returns = evaluate(env, policy, 4, seed=0, deterministic=deterministic)
        assert 1 <= mean <= 200  # CartPole-v0 episodes: 1 to 200 steps, reward 1 per step
        assert (mean, spread) == (round(returns.mean(), 1), round(returns.std(ddof=1), 1))
        assert f"(mean ± sample std; min {returns.min():.1f}, max {returns.max():.1f})" in text
    assert main(["eval", "--checkpoint", str(tmp_path), "--episodes", "1"]) == 0
    one = capsys.readouterr().out
    assert "; 1 episode each\n" in one and "±" not in one  # one episode: no spread
    assert main(["eval", "--checkpoint", str(tmp_path / "none")]) == 2
    assert "not found" in capsys.readouterr().err


@pytest.mark.parametrize(
    "given, message",
    [
        ({"max_steps": 0}, "max_steps must be a positive integer, got 0"),
        ({"deterministic": "no"}, "deterministic must be True or False, got 'no'"),
        ({"seed": 1.5}, "a seed must be an integer, got 1.5"),
    ],
)
def test_evaluate_refuses_what_would_measure_nothing_or_the_wrong_thing(given, message):
    policy = Policy(make_cartpole_params(), None, fppo_jax.make_env("cartpole").action_space, (4,))
    with pytest.raises(InvalidInput, match=message):
        fppo_jax.evaluate(fppo_jax.make_env("cartpole"), policy, 2, **given)


def test_an_unsigned_64_bit_seed_evaluates_as_its_signed_equal():
    env = fppo_jax.make_env("cartpole")
    policy = Policy(make_cartpole_params(), None, env.action_space, (4,))
    unsigned = fppo_jax.evaluate(env, policy, 3, seed=2**64 - 1, deterministic=False)
    signed = fppo_jax.evaluate(env, policy, 3, seed=-1, deterministic=False)
    np.testing.assert_array_equal(unsigned, signed)


def test_evaluate_counts_each_episode_until_it_ends():
    env = fppo_jax.make_env("cartpole")
    policy = Policy(make_cartpole_params(), None, env.action_space, (4,))
    returns = fppo_jax.evaluate(env, policy, 5, seed=0)
    # Always pushing one way ends an episode within a few dozen steps.
    assert returns.shape == (5,) and (returns >= 5).all() and (returns < 60).all()
    np.testing.assert_array_equal(returns, np.round(returns))


def make_cartpole_params():
    from fppo_jax.core.networks import make_networks

    networks = make_networks(fppo_jax.make_env("cartpole").action_space, (4,))
    params = networks.init(jax.random.key(0), 4)["policy"]
    # A constant action: zero weights and a large bias on action 1.
    params = jax.tree.map(jnp.zeros_like, params)
    head = params["params"]["MLP_0"]["Dense_1"]
    head["bias"] = jnp.asarray([0.0, 10.0])
    return params


class Counter(NamedTuple):
    t: jax.Array
    length: jax.Array


class Countdown:
    """Episodes of 1 to 5 steps, their length drawn at reset (-1: episodes never end), then
    `truncate_at` steps at most; reward 1 + action per step, and it goes on being paid past an
    episode's end (nothing resets here), which an evaluation must not count."""

    observation_size = 2
    action_space = Discrete(2)

    def __init__(self, fixed_length: int | None = None, truncate_at: int = 1000):
        self.fixed_length, self.truncate_at = fixed_length, truncate_at

    def reset(self, key):
        length = jax.random.randint(key, (), 1, 6)
        if self.fixed_length is not None:
            length = jnp.asarray(self.fixed_length)
        return Counter(jnp.asarray(0), length), jnp.zeros(2)

    def step(self, key, state, action):
        t = state.t + 1
        state = Counter(t, state.length)
        reward = 1.0 + action
        return state, Step(jnp.zeros(2), reward, t == state.length, t >= self.truncate_at)


def constant_policy(logits) -> Policy:
    """A policy whose action probabilities are softmax(`logits`) whatever it observes."""
    network = make_networks(Discrete(2), (4,)).policy
    shapes = jax.eval_shape(lambda k: network.init(k, jnp.zeros(2)), jax.random.key(0))
    params = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), shapes)
    params["params"]["MLP_0"]["Dense_1"]["bias"] = jnp.asarray(logits, jnp.float32)
    return Policy(params, None, Discrete(2), (4,))


def test_each_episode_counts_its_own_reward_until_it_ends_and_none_after():
    returns = evaluate(Countdown(), constant_policy([0.0, 10.0]), 32, seed=1)
    # Action 1 every step: 2 a step, over episodes of 1 to 5 steps run in lockstep until the
    # longest ends, whose rewards past each one's end are not counted.
    assert set(returns.tolist()) <= {2.0, 4.0, 6.0, 8.0, 10.0}
    assert len(set(returns.tolist())) >= 3  # episodes of several lengths, told apart
    truncated = evaluate(Countdown(fixed_length=-1, truncate_at=3), constant_policy([10.0, 0.0]), 4)
    np.testing.assert_array_equal(truncated, [3.0] * 4)  # action 0: 1 a step, 3 steps


def test_max_steps_ends_episodes_that_never_end():
    returns = evaluate(Countdown(fixed_length=-1), constant_policy([0.0, 10.0]), 3, max_steps=7)
    np.testing.assert_array_equal(returns, [14.0] * 3)


def test_deterministic_takes_the_most_likely_action_and_stochastic_samples():
    env, uniform = Countdown(fixed_length=-1), constant_policy([0.0, 0.0])
    # Both actions equally likely: the most likely is the first (argmax's tie), 1 a step.
    np.testing.assert_array_equal(evaluate(env, uniform, 4, max_steps=50), [50.0] * 4)
    sampled = evaluate(env, uniform, 64, max_steps=50, deterministic=False, seed=2)
    ones = sampled - 50  # how often action 1 was drawn in 50 steps, Binomial(50, ½)
    assert len(set(ones.tolist())) > 5 and ((ones >= 5) & (ones <= 45)).all()
    assert abs(ones.mean() - 25) < 2  # 64 × 50 draws: a standard error of 0.44
    other = evaluate(env, uniform, 64, max_steps=50, deterministic=False, seed=3)
    assert not np.array_equal(other, sampled)  # another seed, other episodes


def test_an_evaluator_is_a_pure_function_of_the_policy_and_a_key_to_vmap_over_policies():
    run = jax.jit(make_evaluator(Countdown(fixed_length=3), 2))
    key = evaluation_key()
    policies = [constant_policy([0.0, 10.0]), constant_policy([10.0, 0.0])]
    np.testing.assert_array_equal(run(policies[0], key), [6.0, 6.0])
    # Called again, the same episodes: with a stochastic policy, the same draws too.
    stochastic = make_evaluator(Countdown(fixed_length=-1), 8, deterministic=False, max_steps=20)
    sampled = jax.jit(stochastic)
    uniform = constant_policy([0.0, 0.0])
    np.testing.assert_array_equal(sampled(uniform, key), sampled(uniform, key))
    assert not np.array_equal(sampled(uniform, key), sampled(uniform, evaluation_key(1)))
    np.testing.assert_array_equal(
        sampled(uniform, key),
        evaluate(Countdown(fixed_length=-1), uniform, 8, deterministic=False, max_steps=20),
    )
    batch = jax.tree.map(lambda *xs: jnp.stack(xs), *policies)
    keys = jnp.stack([key, key])
    np.testing.assert_array_equal(jax.vmap(run)(batch, keys), [[6.0, 6.0], [3.0, 3.0]])


@pytest.mark.parametrize("episodes", [0, -1, 2.0, True])
def test_the_number_of_episodes_is_checked(episodes):
    with pytest.raises(ValueError, match=f"episodes must be a positive integer, got {episodes}"):
        make_evaluator(Countdown(), episodes)
