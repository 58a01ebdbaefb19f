import os
import shutil
import sys
import tempfile

import pytest

# MuJoCo chooses its OpenGL backend when first imported: off-screen EGL unless one was chosen.
os.environ.setdefault("MUJOCO_GL", "egl")
# Two test processes share the machine: neither takes most of an accelerator's memory up front.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
# A few updates of a small batch: enough to exercise every part of an update quickly.
TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
# The same on the command line.
TINY_FLAGS = ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
# A progress callback that reports nothing: the run is called in the chunks progress reporting
# uses (one update each, up to 20 updates), as a run with checkpoints, logs or a callback is. A
# test that compares with such runs, or trains beside them, passes it to share their program.
IN_CHUNKS = {"progress": lambda _: None}


@pytest.fixture
def tiny() -> dict:
    return dict(TINY)


# The longest test files first: each of the two test processes takes a file at a time, so a
# long one taken last would leave the other process idle at the end.
LONGEST_FIRST = (
    "test_study.py",
    "test_distributed.py",
    "test_trainer.py",
    "test_driver.py",
    "test_training.py",
    "test_checkpoint.py",
    "test_sweeps.py",
    "test_tuning.py",
    "test_tuning_rungs.py",
    "test_tune_shapes.py",
    "test_study_tuned.py",
    "test_study_files.py",
    "test_studies.py",
    "test_reuse.py",
    "test_rebuilt_reports.py",
    "test_mjx.py",
    "test_commands.py",
    "test_settings.py",
    "test_surrogates.py",
    "test_native.py",
    "test_gymnasium.py",
    "test_notebooks.py",
    "test_population.py",
    "test_scheduling.py",
    "test_docs_site.py",
    "test_compile_cache.py",
    "test_regression.py",
    "test_gpu_suite.py",
    "test_merge.py",
    "test_plots.py",
    "test_gymnax.py",
    "test_variants.py",
    "test_rollout.py",
    "test_experiment_scripts.py",
    "test_saved_policy.py",
    "test_faults.py",
)


CACHE = pytest.StashKey[str]()


def pytest_configure(config) -> None:
    """One compilation cache for the session, fresh and never the user's: many tests train the
    same small programs (each ``train`` call builds its own), so all but the first load them.
    The process that starts the session makes it; the test processes it starts (pytest-xdist's
    workers, and the command-line and worker subprocesses of tests) inherit it."""
    if not hasattr(config, "workerinput"):
        config.stash[CACHE] = tempfile.mkdtemp(prefix="fppo-jax-test-cache-")
        os.environ["FPPO_JAX_CACHE_DIR"] = config.stash[CACHE]


def pytest_unconfigure(config) -> None:
    if CACHE in config.stash:
        shutil.rmtree(config.stash[CACHE], ignore_errors=True)


@pytest.fixture(scope="session", autouse=True)
def session_compile_cache() -> None:
    """The session's cache also for the programs tests compile without ``train`` (``train``
    and ``sweep`` turn it on themselves)."""
    from fppo_jax.run import compile_cache

    compile_cache.enable()


def pytest_collection_modifyitems(items: list) -> None:
    def rank(item) -> int:
        name = item.path.name
        return LONGEST_FIRST.index(name) if name in LONGEST_FIRST else len(LONGEST_FIRST)

    items.sort(key=rank)  # stable: a file's own tests keep their order


@pytest.fixture(scope="session")
def saved_policies(tmp_path_factory) -> dict:
    """A discrete policy (CartPole's sizes, with observation statistics) and a continuous one
    (Pendulum's, raw observations, its head scaled up so that its actions often reach their
    bounds), initialised, not trained, and saved: {"discrete": dir, "continuous": dir}."""
    import jax
    import jax.numpy as jnp

    from fppo_jax.core.networks import make_networks
    from fppo_jax.core.normalization import RunningStats
    from fppo_jax.core.policy import Policy
    from fppo_jax.envs import Box, Discrete
    from fppo_jax.store.saved_policy import save_policy

    def policy(space, size: int, stats: bool, seed: int) -> Policy:
        key, mean_key, var_key = jax.random.split(jax.random.key(seed), 3)
        obs = jnp.zeros((size,))
        params = make_networks(space, (64, 64)).policy.init(key, obs)
        params = jax.tree_util.tree_map_with_path(
            lambda path, x: x * 1000 if "Dense_2" in jax.tree_util.keystr(path) else x, params
        )
        obs_stats = None
        if stats:
            mean = jax.random.normal(mean_key, (size,))
            var = jnp.exp(jax.random.normal(var_key, (size,)))
            obs_stats = RunningStats(mean, var, jnp.asarray(100.0))
        return Policy(params, obs_stats, space, (64, 64))

    where = tmp_path_factory.mktemp("policies")
    made = {
        "discrete": policy(Discrete(2), 4, True, 0),
        "continuous": policy(Box((-2.0,), (2.0,)), 3, False, 1),
    }
    record = {"config": {"env": "a test's"}, "update": 0}
    return {name: save_policy(where / name, p, record) for name, p in made.items()}


@pytest.fixture
def module_here(tmp_path, monkeypatch):
    """Writes a module in a new current directory that is not on Python's path (as under the
    installed command); the module is forgotten afterwards."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", os.getcwd())])

    def write(name, text):
        (tmp_path / f"{name}.py").write_text(text)
        monkeypatch.delitem(sys.modules, name, raising=False)

    return write
