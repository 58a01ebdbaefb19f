import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import IN_CHUNKS
from gymnax.environments.classic_control import CartPole

import fppo_jax
from fppo_jax import METRICS, TrainConfig, hyperparameters, make_env, make_train, train
from fppo_jax.core.config import describe, preset_config, resolve_config
from fppo_jax.core.trainer import RETURN_WINDOW, _average_return, _push_returns


def test_same_seed_gives_identical_metrics(tiny):
    first = train("cartpole", "fppo-lp", seed=3, total_steps=512, **tiny)
    second = train("cartpole", "fppo-lp", seed=3, total_steps=512, **tiny)
    other = train("cartpole", "fppo-lp", seed=4, total_steps=512, **tiny)
    assert set(first.metrics) == set(METRICS)
    for name in METRICS:
        np.testing.assert_array_equal(first.metrics[name], second.metrics[name])
    assert not np.array_equal(first.metrics["policy_loss"], other.metrics["policy_loss"])


def test_one_row_per_update_and_chunks_change_nothing(tiny):
    whole = train("cartpole", "tr-ppo", total_steps=4 * 128, **tiny)
    reports = []
    chunked = train("cartpole", "tr-ppo", total_steps=4 * 128, progress=reports.append, **tiny)
    assert len(whole.metrics["env_steps"]) == 4
    assert whole.metrics["env_steps"].tolist() == [128, 256, 384, 512]
    for name in METRICS:
        np.testing.assert_array_equal(whole.metrics[name], chunked.metrics[name])
    assert [r.update for r in reports] == [0, 1, 2, 3, 4]
    assert reports[-1].env_steps == 512 and reports[-1].total_steps == 512


def test_a_chunk_past_the_run_end_updates_nothing(tiny):
    """A chunk longer than what is left of the run makes the updates left, gives NaN rows
    (env_steps -1) for the rest and leaves the state where the run ended, alone and vmapped."""
    config = TrainConfig(total_steps=3 * 128, **tiny)
    trainer = make_train(config, make_env("cartpole"))
    key, hp = jax.random.key(0), hyperparameters("ppo")
    chunk = jax.jit(lambda state, hp: trainer.run(state, hp, 2))
    started = jax.jit(trainer.init)(key, hp)
    halfway, first = chunk(started, hp)
    state, second = chunk(halfway, hp)
    after_end, third = chunk(state, hp)
    steps = np.concatenate([first.env_steps, second.env_steps, third.env_steps])
    assert steps.tolist() == [128, 256, 384, -1, -1, -1]
    assert np.isfinite(second.policy_loss[0]) and np.isnan(second.policy_loss[1])
    assert np.isnan(np.stack(third[1:])).all()
    assert int(state.update) == int(after_end.update) == 3
    learnt = lambda s: jax.tree.leaves((s.params, s.opt_state, s.obs_stats, s.envs))  # noqa: E731
    for ended, unchanged in zip(learnt(state), learnt(after_end), strict=True):
        np.testing.assert_array_equal(ended, unchanged)
    # Vmapped runs at different updates: one ends within the chunk, the other does not.
    runs = jax.tree.map(lambda *x: jnp.stack(x), halfway, started)
    hps = jax.tree.map(lambda x: jnp.stack([x, x]), hp)
    _, vmapped = jax.jit(jax.vmap(lambda s, h: trainer.run(s, h, 2)))(runs, hps)
    assert vmapped.env_steps.tolist() == [[384, -1], [128, 256]]
    assert np.isnan(vmapped.policy_loss[0, 1]) and np.isfinite(vmapped.policy_loss[1]).all()


def test_cartpole_learns_with_ppo():
    # 24 updates in chunks of 2: the program of the README's first run and of the CartPole pin.
    result = train("cartpole", "ppo", total_steps=49_152, **IN_CHUNKS)
    assert np.nanmax(result.metrics["average_return"]) > 120
    # The policy acts on raw observations; deterministic without a key.
    obs = jnp.zeros((3, 4))
    assert result.policy(obs).shape == (3,)
    np.testing.assert_array_equal(result.policy(obs), result.policy(obs))
    assert result.policy(obs[0], jax.random.key(0)).shape == ()


@pytest.mark.slow  # about 20 s on a CPU, most of it compiling
def test_pendulum_learns_with_ppo():
    # A random policy scores about -1200 to -1400 an episode; seeds 0, 1 and 2 end near -210.
    returns = train("gymnax/Pendulum-v1", "ppo", total_steps=100_000).metrics["average_return"]
    assert returns[np.isfinite(returns)][0] < -1000  # the untrained policy's episodes
    assert returns[-1] > -400


def test_metrics_are_in_range(tiny):
    m = train("cartpole", "fppo-qp", total_steps=4 * 128, **tiny).metrics
    for name in ("clip_fraction", "negative_fraction_before", "negative_fraction_after"):
        assert np.all((m[name] >= 0) & (m[name] <= 1))
    assert np.all(m["entropy"] > 0) and np.all(m["entropy"] <= np.log(2) + 1e-6)
    assert np.all(m["approx_kl"] >= 0)
    # The first update starts from the rollout policy itself: ratio 1, so nothing in R±.
    assert m["negative_fraction_before"][0] == 0.0


def test_a_gymnax_environment_object_is_accepted(tiny):
    # The shape of test_same_seed_gives_identical_metrics: the program it compiled is reused.
    result = train(CartPole(), "fppo-lp", total_steps=512, **tiny)
    assert result.config["env"] == "CartPole"
    assert len(result.metrics["env_steps"]) == 4


def test_vmapped_seeds_and_variants_match_single_runs(tiny):
    config = TrainConfig(total_steps=256, **tiny)
    trainer = make_train(config, make_env("cartpole"))
    hps = [hyperparameters("ppo"), hyperparameters("fppo-lp", alpha=1.5)]
    keys = jax.random.split(jax.random.key(0), 2)
    stacked = jax.tree.map(lambda *xs: jnp.stack(xs), *hps)
    _, batched = jax.jit(jax.vmap(trainer))(keys, stacked)
    for i, hp in enumerate(hps):
        _, single = jax.jit(trainer)(keys[i], hp)
        for name in METRICS:
            np.testing.assert_allclose(
                getattr(batched, name)[i], getattr(single, name), rtol=2e-4, atol=1e-5
            )


def test_ring_buffer_keeps_the_last_100_episodes_in_order():
    recent, count = jnp.zeros(RETURN_WINDOW), jnp.asarray(0, jnp.int32)
    returns = jnp.arange(1.0, 251.0).reshape(50, 5)
    every_other = jnp.arange(250).reshape(50, 5) % 2 == 0  # 125 finished episodes
    recent, count = _push_returns(recent, count, every_other, returns)
    assert int(count) == 125
    finished = np.asarray(returns)[np.asarray(every_other)]
    assert float(_average_return(recent, count)) == pytest.approx(finished[-100:].mean())
    assert np.isnan(float(_average_return(jnp.zeros(RETURN_WINDOW), jnp.asarray(0))))


def test_bad_settings_fail_before_compiling():
    with pytest.raises(ValueError, match="unknown environment 'hoper'"):
        train("hoper")
    with pytest.raises(ValueError, match="unknown variant 'ppo2'"):
        train("cartpole", "ppo2")
    with pytest.raises(ValueError, match="unknown setting lr; valid: total_steps"):
        train("cartpole", lr=1e-3)
    with pytest.raises(ValueError, match="learning_rate must be > 0"):
        train("cartpole", learning_rate=-1.0)
    with pytest.raises(ValueError, match="gamma must be in \\(0, 1\\]"):
        train("cartpole", gamma=1.5)
    with pytest.raises(ValueError, match="num_minibatches \\(3\\) must divide"):
        train("cartpole", num_minibatches=3)
    with pytest.raises(ValueError, match="less than one update's samples"):
        train("cartpole", total_steps=100)
    with pytest.raises(ValueError, match="alpha must be >= 1 for fppo-lp"):
        fppo_jax.train("cartpole", "fppo-lp", 0.8)


def test_task_defaults_follow_table_2():
    # The one resolution that train and sweep share (a run's config records its result).
    from fppo_jax.core.resolution import resolve_hyperparameters
    from fppo_jax.run.sweeps import expand_grid

    assert resolve_hyperparameters("fppo-lp", "cartpole")[1]["alpha"] == 1.3
    assert resolve_hyperparameters("fppo-qp", "hopper")[1]["k"] == 0.2
    assert resolve_hyperparameters("fppo-lp", "reacher", alpha=1.2)[1]["alpha"] == 1.2
    assert expand_grid({"variant": ["fppo-lp", "fppo-qp"]}, "swimmer") == [
        {"variant": "fppo-lp", "alpha": 1.1},
        {"variant": "fppo-qp", "k": 0.1},
    ]


def test_the_paper_preset_anneals_the_learning_rate_on_mujoco_tasks_only():
    # baselines' ppo2: `lr=lambda f: 3e-4 * f` with its MuJoCo defaults, constant elsewhere.
    for task in ("hopper", "walker2d", "halfcheetah", "ant", "reacher", "swimmer"):
        config = resolve_config(task, None, {})
        assert config.anneal_learning_rate and config.total_steps == 1_000_000
        assert describe(config, "paper").endswith("learning rate annealed linearly to 0")
    assert not resolve_config("hopper", None, {"anneal_learning_rate": False}).anneal_learning_rate
    assert not resolve_config("hopper", None, {}, preset="massive").anneal_learning_rate
    for task in ("cartpole", "acrobot", "mountaincar", "gymnax/Pendulum-v1"):
        assert not resolve_config(task, None, {}).anneal_learning_rate


def test_presets_set_the_shape_and_overrides_win():
    massive = preset_config("massive", total_steps=10**7)
    assert (massive.num_envs, massive.num_steps, massive.samples_per_update) == (2048, 16, 32768)
    assert massive.resets_per_rollout == 1
    assert preset_config("paper", total_steps=10**6) == TrainConfig(total_steps=10**6)
    with pytest.raises(ValueError, match="unknown preset 'huge'; valid presets: paper, massive"):
        train("cartpole", preset="huge")
    result = train(
        "cartpole",
        "ppo",
        preset="massive",
        total_steps=256,
        num_envs=8,
        num_steps=16,
        num_minibatches=2,
        num_epochs=1,
    )
    assert result.config["preset"] == "massive" and result.config["resets_per_rollout"] == 1
    assert result.config["num_envs"] == 8
    assert "(preset massive)" in result.summary()


def test_escape_by_epoch_ends_where_the_update_does(tiny):
    # Eight epochs at a high learning rate, so that samples do leave the trust region.
    config = fppo_jax.TrainConfig(total_steps=128 * 3, **{**tiny, "num_epochs": 8})
    trainer = make_train(config, make_env("cartpole"))
    hp = hyperparameters("fppo-lp", alpha=1.3, learning_rate=3e-3)

    # One program (each of its parts compiled alone took seconds): two updates, then the next
    # update's escape by epoch, the update itself, and the escape given the batch it collects.
    @jax.jit
    def after_two_updates(key):
        state, _ = trainer.run(trainer.init(key, hp), hp, 2)
        rollout_key = jax.random.split(state.key, 3)[1]
        batch = trainer.collect(state, hp, rollout_key)[0]
        by_epoch = trainer.escape_by_epoch(state, hp)
        return by_epoch, trainer.update(state, hp)[1], trainer.escape_by_epoch(state, hp, batch)

    by_epoch, metrics, given = after_two_updates(jax.random.key(0))
    by_epoch = np.asarray(by_epoch)
    assert by_epoch.shape == (config.num_epochs,)
    assert ((by_epoch >= 0) & (by_epoch <= 1)).all() and by_epoch.max() > 0.05
    # The same batch and minibatch order as the update: its last epoch is the update's result.
    np.testing.assert_allclose(by_epoch[-1], metrics.negative_fraction_after, atol=1e-6)
    # Given the batch the update collects, the same epochs.
    np.testing.assert_array_equal(given, by_epoch)
