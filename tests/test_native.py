"""gym's MuJoCo tasks in native MuJoCo (envpool), stepped from inside the compiled program."""

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import fppo_jax
from fppo_jax import TrainConfig, hyperparameters, make_env, make_train
from fppo_jax.cli import main
from fppo_jax.envs import Box, choose_backend, native
from fppo_jax.envs.native import NativeEnvironment

if not native.envpool_installed():
    pytest.skip("the native backend's envpool is Linux-only", allow_module_level=True)

TINY = {"total_steps": 256, "num_envs": 4, "num_steps": 32, "num_minibatches": 2, "num_epochs": 2}


def _episode(env, seed, actions):
    """Step two environments of `env` through `actions` [step, env, action], in one program."""

    @jax.jit
    def run(key):
        state, obs = jax.vmap(env.reset)(jax.random.split(key, 2))

        def step(state, action):
            return jax.vmap(env.step)(jax.random.split(key, 2), state, action)

        return obs, jax.lax.scan(step, state, actions)[1]

    return run(jax.random.key(seed))


def test_reacher_matches_envpool_and_is_truncated_at_50_steps_then_starts_afresh():
    env = make_env("reacher", "native")
    assert isinstance(env, NativeEnvironment) and env.task_id == "Reacher-v2"
    assert env.observation_size == 11 and env.action_space == Box((-1.0,) * 2, (1.0,) * 2)
    actions = np.random.default_rng(0).uniform(-1, 1, (53, 2, 2)).astype(np.float32)
    first, out = _episode(env, 0, jnp.asarray(actions))

    # The same environments stepped by envpool itself, seeded as the adapter seeds them.
    seeds = native.seeds_of(jax.random.key_data(jax.random.split(jax.random.key(0), 2)))
    pool = native.import_envpool().make(
        "Reacher-v2", env_type="gymnasium", num_envs=2, env_seed=seeds
    )
    obs, _ = pool.reset()
    np.testing.assert_allclose(first, obs, rtol=1e-6)
    for t in range(50):
        obs, reward, _, _, _ = pool.step(actions[t].astype(np.float64))
        np.testing.assert_allclose(out.obs[t], obs, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(out.reward[t], reward, rtol=1e-5, atol=1e-6)
    truncated = np.asarray(out.truncated)
    assert truncated[49].all() and truncated.sum() == 2 and not np.asarray(out.terminated).any()
    # The step that ends an episode gives its final observation, and the new one's first to
    # act on; every other step gives the same observation twice.
    next_obs = np.asarray(out.next_obs)
    np.testing.assert_array_equal(np.delete(next_obs, 49, 0), np.delete(out.obs, 49, 0))
    assert not np.allclose(next_obs[49], out.obs[49])
    # envpool's own next step resets instead of stepping: the same new episode.
    obs, *_ = pool.step(actions[50].astype(np.float64))
    np.testing.assert_allclose(next_obs[49], obs, rtol=1e-6)


def test_hopper_terminates_when_it_falls_and_is_not_truncated():
    env = make_env("hopper", "native")
    actions = jnp.ones((120, 2, 3))  # full torque: it falls within a hundred steps
    # (the same action at every step: each call of the host differs by the steps taken)
    _, out = _episode(env, 1, actions)
    terminated = np.asarray(out.terminated)
    assert terminated.any(axis=0).all() and not np.asarray(out.truncated).any()
    ends = terminated.argmax(axis=0)
    for i, t in enumerate(ends):  # a new episode begins right after, near the start pose
        assert not np.allclose(out.next_obs[t, i], out.obs[t, i])
        np.testing.assert_allclose(out.next_obs[t, i, 0], 1.25, atol=0.01)  # torso height


@pytest.fixture(scope="module")
def swimmer_run():
    """A tiny FPPO-QP run on native Swimmer: its trainer, hyperparameters and jitted program."""
    trainer = make_train(TrainConfig(**TINY), make_env("swimmer", "native"))
    return trainer, hyperparameters("fppo-qp", k=0.1), jax.jit(trainer)


def test_same_seed_gives_the_same_run_and_a_sweep_run_matches_it(swimmer_run):
    trainer, hp, run = swimmer_run
    first, second = run(jax.random.key(3), hp)[1], run(jax.random.key(3), hp)[1]
    for name, a, b in zip(first._fields, first, second, strict=True):
        np.testing.assert_array_equal(a, b, err_msg=name)
    keys = jnp.stack([jax.random.key(3), jax.random.key(4)])
    hps = jax.tree.map(lambda x: jnp.stack([x, x]), hp)
    batched = jax.jit(jax.vmap(trainer))(keys, hps)[1]
    np.testing.assert_allclose(batched.policy_loss[0, 0], first.policy_loss[0], rtol=1e-4)
    assert not np.allclose(batched.policy_loss[1], batched.policy_loss[0])


def test_truncation_is_bootstrapped_and_termination_is_not():
    env = make_env("reacher", "native")
    config = TrainConfig(total_steps=120, num_envs=2, num_steps=60, num_minibatches=1)
    trainer = make_train(config, env)
    hp = hyperparameters("ppo")
    state = trainer.init(jax.random.key(0), hp)
    traj, envs = jax.jit(trainer._rollout)(state, hp, jax.random.key(1))
    truncated = np.asarray(traj.truncated)
    assert np.flatnonzero(truncated[:, 0]).tolist() == [49]
    final, raw = np.asarray(traj.final_obs), np.asarray(traj.raw_obs)
    np.testing.assert_array_equal(final[:49], raw[1:50])  # mid-episode: the next one acted on
    assert not np.allclose(final[49], raw[50])  # at truncation: the last state's, not the reset's
    np.testing.assert_array_equal(np.asarray(envs.obs), final[-1])
    assert np.asarray(envs.episode_return).any() and np.asarray(traj.episode_return[50]).any()


def test_a_resumed_native_run_restarts_its_environments_and_keeps_its_learning(tmp_path, capsys):
    settings = {**TINY, "total_steps": 512, "checkpoint_dir": tmp_path, "checkpoint_every": 2}
    stopped = fppo_jax.train(
        "hopper", "ppo", backend="native", callback=lambda s: s.update < 2, **settings
    )
    assert stopped.stopped_at == 2
    resumed = fppo_jax.train("hopper", "ppo", backend="native", resume=True, **settings)
    assert resumed.resumed_from == 2
    assert "(preset paper, native MuJoCo), resumed at update 2 in fresh environments" in (
        resumed.summary()
    )
    assert "resuming at update 2 in fresh environments" in capsys.readouterr().err
    assert resumed.config["backend"] == "native" and int(resumed.state.update) == 4
    for name in ("policy_loss", "average_return", "value_loss"):
        np.testing.assert_array_equal(resumed.metrics[name][:2], stopped.metrics[name])
    assert np.isfinite(resumed.metrics["policy_loss"]).all()
    # What was learnt goes on: the normalisers have seen all four rollouts, and the episodes
    # finished before the stop still count in the average return.
    samples = TINY["num_envs"] * TINY["num_steps"]
    assert float(resumed.state.obs_stats.count) == pytest.approx(4 * samples, abs=1e-3)
    assert int(resumed.state.num_episodes) > int(stopped.state.num_episodes)


def test_variants_are_compared_on_one_collected_batch(swimmer_run):
    trainer, hp, run = swimmer_run
    state = run(jax.random.key(0), hp)[0]
    collect = jax.jit(trainer.collect)
    first, second = (
        collect(state, hp, jax.random.key(1))[0],
        collect(state, hp, jax.random.key(1))[0],
    )
    # The pool has gone on: the same state and key roll out other samples.
    assert not np.allclose(first.obs, second.obs)
    probe = jax.jit(trainer.escape_by_epoch)
    lp = hyperparameters("fppo-lp", alpha=1.1)
    np.testing.assert_array_equal(probe(state, lp, first), probe(state, lp, first))
    assert probe(state, lp, first).shape == (TINY["num_epochs"],)


def test_restart_envs_keeps_everything_learnt_and_starts_new_episodes(swimmer_run):
    trainer, hp, run = swimmer_run
    state = run(jax.random.key(0), hp)[0]
    fresh = jax.jit(trainer.restart_envs)(state)
    for part in ("params", "opt_state", "obs_stats", "return_stats", "recent_returns"):
        for a, b in zip(
            jax.tree.leaves(getattr(fresh, part)),
            jax.tree.leaves(getattr(state, part)),
            strict=True,
        ):
            np.testing.assert_array_equal(a, b, err_msg=part)
    assert int(fresh.envs.state.pool[0]) != int(state.envs.state.pool[0])
    assert not np.asarray(fresh.envs.episode_return).any()
    assert not np.allclose(fresh.envs.obs, state.envs.obs)


def test_auto_picks_native_on_a_cpu_and_says_why(monkeypatch):
    assert choose_backend("hopper") == ("native", "auto: JAX runs on the CPU")
    assert choose_backend("cartpole") == ("gymnax", "")
    assert choose_backend("hopper", "mjx") == ("mjx", "")
    monkeypatch.setattr(native, "envpool_installed", lambda: False)
    backend, why = choose_backend("hopper")
    assert backend == "mjx" and "pip install 'fppo-jax[native]'" in why
    with pytest.raises(ValueError, match=r"pip install 'fppo-jax\[native\]'"):
        choose_backend("hopper", "native")


@pytest.mark.parametrize(
    ("env", "backend", "message"),
    [
        ("cartpole", "native", r"cartpole has no native version; tasks with one: hopper, "),
        ("cartpole", "mjx", r"cartpole runs on gymnax, not MJX"),
        ("hopper", "physx", r"unknown backend 'physx'; valid backends: auto, mjx, native"),
        ("native/Hopper-v9", "native", r"no task 'Hopper-v9'; did you mean Hopper-v\d or "),
    ],
)
def test_a_backend_that_cannot_run_the_task_is_refused(env, backend, message):
    with pytest.raises(ValueError, match=message):
        fppo_jax.train(env, "ppo", backend=backend, **TINY)


def test_the_cli_trains_natively_and_refuses_many_devices(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(
        [
            *("train", "--env", "native/Swimmer-v4", "--backend", "native", "--variant", "ppo"),
            *("--steps", "256", "--num-envs", "4", "--num-steps", "32", "--quiet"),
            *("--num-minibatches", "2", "--num-epochs", "1", "--output", str(out)),
        ]
    )
    assert code == 0
    assert '"backend": "native"' in (out / "config.json").read_text()
    code = main(["train", "--env", "hopper", "--backend", "native", "--devices", "2"])
    assert code == 2 and "devices must be 1" in capsys.readouterr().err


def test_a_two_setting_native_sweep_is_one_program_over_one_pool(tmp_path):
    result = fppo_jax.sweep(
        "swimmer",
        {"variant": ["ppo", "fppo-qp"]},
        seeds=[0, 1],
        backend="native",
        total_steps=256,
        log_dir=tmp_path,
        **{k: v for k, v in TINY.items() if k != "total_steps"},
    )
    assert result.config["backend"] == "native" and result.config["runs_per_call"] == 4
    assert [(run["setting"], run["seed"]) for run in result.runs] == [
        (0, 0),
        (0, 1),
        (1, 0),
        (1, 1),
    ]
    losses = result.metrics["policy_loss"]
    assert losses.shape == (4, 2) and np.isfinite(losses).all()
    # A seed's environments are the same under either setting, and in so short a run no sample
    # gets past the clip range, where FPPO-QP and PPO differ; the two seeds differ.
    np.testing.assert_array_equal(losses[0], losses[2])
    np.testing.assert_array_equal(losses[1], losses[3])
    assert not np.allclose(losses[0], losses[1])
    assert '"backend": "native"' in (tmp_path / "sweep.json").read_text()


def test_the_native_backend_leaves_the_process_environment_as_it_was():
    # envpool's own import sets MPLBACKEND=Agg, which silences every figure a script or a
    # notebook kernel started from this process would show.
    code = textwrap.dedent("""
        import os
        import fppo_jax
        before = dict(os.environ)
        fppo_jax.make_env("reacher", "native")
        fppo_jax.envs.native.import_envpool()
        print(sorted(k for k in {*before, *os.environ} if before.get(k) != os.environ.get(k)))
    """)
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


@pytest.mark.parametrize(
    "given, cores", [(None, 64), ("2", 2), ("128", 64), ("0", 64), ("two", 64), ("", 64)]
)
def test_threads_follow_slurm_s_cpus_per_task_on_a_node_left_unbound(monkeypatch, given, cores):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(64)), raising=False)
    if given is None:
        monkeypatch.delenv("SLURM_CPUS_PER_TASK", raising=False)
    else:
        monkeypatch.setenv("SLURM_CPUS_PER_TASK", given)
    assert native.usable_cores() == cores


def test_a_native_sweep_evaluates_each_run_on_environments_of_its_own():
    """Evaluating a sweep's runs steps a pool of every run's episodes: runs whose policies are
    the same (a seed under either setting, as above) score the same episodes alike, where runs
    sharing one evaluation's environments would step each other's."""
    result = fppo_jax.sweep(
        "swimmer",
        {"variant": ["ppo", "fppo-qp"]},
        seeds=[0, 1],
        backend="native",
        eval_every=2,
        eval_episodes=2,
        **TINY,
    )
    np.testing.assert_array_equal(
        result.metrics["policy_loss"][0], result.metrics["policy_loss"][2]
    )
    evaluated = result.metrics["eval_return"][:, -1]
    assert np.isfinite(evaluated).all()
    assert evaluated[0] == evaluated[2] and evaluated[1] == evaluated[3]
    assert evaluated[0] != evaluated[1]
