"""Where one update's time goes: each compiled part of it timed on its own.

    python experiments/profile_update.py [--repeats 200]

Parts: the environment alone (random actions, the same number of steps as a rollout), the
rollout (policy + environment), the epochs of minibatch updates, and the whole update.
Settings: PureJaxRL's CartPole (see purejaxrl_settings.py).
"""

import argparse
import time

import jax
import jax.numpy as jnp

import purejaxrl_settings as pjr
from fppo_jax import make_train


def seconds_per_call(fn, *args, repeats, blocks=7):
    """The best of `blocks` timings of `repeats` calls: the least disturbed by the machine."""
    jax.block_until_ready(fn(*args))
    best = float("inf")
    for _ in range(blocks):
        start = time.perf_counter()
        for _ in range(repeats):
            out = fn(*args)
        jax.block_until_ready(out)
        best = min(best, (time.perf_counter() - start) / repeats)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()

    env, config, hp = pjr.env(), pjr.config(), pjr.hp()
    trainer = make_train(config, env)
    state = jax.jit(trainer.init)(jax.random.key(0), hp)

    def env_alone(key):
        def step(carry, k):
            env_state = carry
            action_key, step_key = jax.random.split(k)
            actions = jax.random.randint(action_key, (config.num_envs,), 0, 2)
            env_state, out = jax.vmap(env.step)(jax.random.split(step_key, config.num_envs), env_state, actions)
            return env_state, out.reward
        return jax.lax.scan(step, state.env_state, jax.random.split(key, config.num_steps))[1].sum()

    rollout = jax.jit(lambda s, k: trainer._rollout(s, hp, k)[0])
    traj = rollout(state, jax.random.key(1))
    update = jax.jit(trainer.update)

    # The batch the epochs consume, built the way `update` builds it.
    from fppo_jax.losses import Batch
    flat = lambda x: x.reshape((config.samples_per_update, *x.shape[2:]))  # noqa: E731
    n = traj.reward.shape
    batch = jax.tree.map(flat, Batch(traj.obs, traj.action, traj.log_prob, jnp.zeros(n), jnp.ones(n),
                                     jnp.ones(n), traj.distribution))
    epochs = jax.jit(lambda s, b, k: trainer._epochs(s, hp, b, k))

    parts = {
        "environment alone": seconds_per_call(jax.jit(env_alone), jax.random.key(2), repeats=args.repeats),
        "rollout (policy + env)": seconds_per_call(rollout, state, jax.random.key(1), repeats=args.repeats),
        "epochs (minibatch updates)": seconds_per_call(epochs, state, batch, jax.random.key(3), repeats=args.repeats),
        "whole update": seconds_per_call(update, state, hp, repeats=args.repeats),
    }
    whole = parts["whole update"]
    print(f"{config.samples_per_update} samples per update; {jax.devices()[0].device_kind}")
    for name, seconds in parts.items():
        print(f"{name:<28} {seconds * 1e3:8.3f} ms  {seconds / whole:6.1%} of an update")
    print(f"update throughput: {config.samples_per_update / whole:,.0f} env steps/s")


if __name__ == "__main__":
    main()
