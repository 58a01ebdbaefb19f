"""Environments and checks shared by the tests."""

import contextlib
import dataclasses
import io
import json
import runpy
import subprocess
import sys
import traceback
from pathlib import Path
from unittest import mock

import jax
import jax.numpy as jnp
import numpy as np
from conftest import TINY

from fppo_jax import METRICS, SweepResult
from fppo_jax.core.config import TrainConfig
from fppo_jax.envs import Step, make_env
from fppo_jax.store.record import RunRecord


@dataclasses.dataclass(frozen=True)
class NaNRewardAfter:
    """CartPole whose reward turns NaN after `start` steps of an episode."""

    start: int
    inner: object = dataclasses.field(default_factory=lambda: make_env("cartpole"))
    observation_size = 4

    @property
    def action_space(self):
        return self.inner.action_space

    def reset(self, key):
        return self.inner.reset(key)

    def step(self, key, state, action):
        state, out = self.inner.step(key, state, action)
        reward = jnp.where(state.time >= self.start, jnp.nan, out.reward)
        return state, Step(out.obs, reward, out.terminated, out.truncated)


def assert_bitwise_equal(a, b) -> None:
    """Every leaf of pytrees `a` and `b` equal bit for bit (NaN equal to NaN; PRNG keys by
    their data)."""
    leaves_a, leaves_b = jax.tree.leaves(a), jax.tree.leaves(b)
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for x, y in zip(leaves_a, leaves_b, strict=True):
        if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
            x, y = jax.random.key_data(x), jax.random.key_data(y)
        x, y = np.asarray(x), np.asarray(y)
        assert x.dtype == y.dtype and x.shape == y.shape
        assert x.tobytes() == y.tobytes()


def sweep_by_hand() -> SweepResult:
    """Three settings × three seeds, three updates of 128 env steps: two of ppo's runs diverged
    (their returns and fractions are far off, to show they are left out), and all of fppo-lp's."""
    settings = [
        {"variant": "ppo"},
        {"variant": "fppo-lp", "alpha": 1.3},
        {"variant": "tr-ppo", "delta": 0.02},
    ]
    runs = [{"setting": s, "seed": seed} for s in range(3) for seed in range(3)]
    metrics = {name: np.full((9, 3), 0.5) for name in METRICS}
    metrics["env_steps"] = np.tile(128 * np.arange(1, 4), (9, 1))
    metrics["average_return"] = np.array(
        [[10, 30, 20], [900, 900, 900], [900, 900, 900]]
        + [[np.nan, 1, 2]] * 3
        + [[10, 20, 30], [20, 40, 60], [30, 60, 90]],
        float,
    )
    metrics["negative_fraction_after"][1:3] = 1.0
    return SweepResult(
        settings=settings,
        seeds=[0, 1, 2],
        runs=runs,
        metrics=metrics,
        diverged=np.array([0, 3, 2, 3, 2, 3, 0, 0, 0]),
        config={"env": "cartpole"},
        compile_seconds=0.0,
        train_seconds=0.0,
    )


def run_script(path: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    """Script `path` run with `args` from `cwd` as ``python path args`` runs it, but in this
    process, whose imports and compiled programs it reuses (a fresh process takes seconds to
    start): its exit status, as Python's would be, and what it printed."""
    argv, out, err = [str(path), *args], io.StringIO(), io.StringIO()
    folder = [] if path.is_dir() else [str(path.parent)]  # runpy puts a folder there itself
    with (
        contextlib.chdir(cwd),
        mock.patch.object(sys, "argv", argv),
        mock.patch.object(sys, "path", [*folder, *sys.path]),
        contextlib.redirect_stdout(out),
        contextlib.redirect_stderr(err),
    ):
        try:
            runpy.run_path(str(path), run_name="__main__")
            status = 0
        except SystemExit as stopped:  # what the interpreter makes of it
            if stopped.code is None or isinstance(stopped.code, int):
                status = stopped.code or 0
            else:
                print(stopped.code, file=sys.stderr)
                status = 1
        except Exception:
            traceback.print_exc()
            status = 1
    return subprocess.CompletedProcess(argv, status, out.getvalue(), err.getvalue())


# A tiny tune: four trials per arm halved by 2 over 8 updates, rungs of 4, 2 and 1 trials ending
# at updates 2, 4 and 8.
# The race at its cheapest: the default and one finalist on 4 validation seeds (at level 0.1, the
# smallest that 4 seeds can reach) make 16 runs, the first rung's shape, so its program is the
# first rung's; trials ranked on the training return, which needs no evaluation program.
TUNE_RACE = dict(finalists=1, validation_seeds=4, race_level=0.1, score="train")
TUNE_SMALL = dict(trials=4, eta=2, seeds=2, total_steps=8 * 128, progress=False, **TUNE_RACE)
TUNE_SMALL |= TINY
TUNE_ARMS = ["ppo", "fppo-lp"]


def rung_scores(directory: Path, task: str = "cartpole") -> list[dict]:
    """A tune's recorded rungs' scores on `task`, in order."""
    rungs = sorted((directory / task).glob("rung-*/scores.json"))
    return [json.loads(path.read_text()) for path in rungs]


def two_settings(shift: float = 100.0, seeds: int = 8) -> SweepResult:
    """PPO and FPPO-LP over `seeds` seeds, FPPO-LP's final returns `shift` above PPO's."""
    settings = [{"variant": "ppo"}, {"variant": "fppo-lp", "alpha": 1.3}]
    runs = [{"setting": s, "seed": seed} for s in range(2) for seed in range(seeds)]
    final = np.concatenate([np.arange(seeds), np.arange(seeds) + shift])
    curves = np.stack([np.linspace(0, f, 4) for f in final])
    metrics = {name: np.zeros_like(curves) for name in METRICS}
    metrics.update(average_return=curves, env_steps=np.tile(np.arange(1, 5) * 64, (len(runs), 1)))
    return SweepResult(
        settings=settings,
        seeds=list(range(seeds)),
        runs=runs,
        metrics=metrics,
        diverged=np.zeros(len(runs), np.int64),
        config=RunRecord(
            "cartpole",
            "gymnax",
            "paper",
            TrainConfig(),
            seeds=tuple(range(seeds)),
            runs_per_call=len(runs),
        ).to_json(),
        compile_seconds=1.0,
        train_seconds=2.0,
    )


# Seeds that name no distinct valid seeds, each with the refusal: checked once
# (fppo_jax.core.checks.check_seeds), and before anything is made where a run takes them.
BAD_SEEDS = [
    ([1, 1], "seeds must be distinct, got [1, 1]"),
    (["1"], "a seed must be an integer, got '1'"),
    ([2**70], "a seed must fit in 64 bits"),
    ("5", "seeds must be a count or a sequence of integers, got '5'"),
    (0, "seeds must be a positive integer, got 0"),
    ([], "seeds must name at least one seed, got []"),
    (np.array(2), "seeds must be a count or a sequence of integers, got array(2)"),
    (10**9, "at most 100,000 seeds may be given, got 1,000,000,000"),
    ([0, 1, 2**32], "seeds 0 and 4294967296 give the same key"),
    ([-1, 2**32 - 1], "seeds -1 and 4294967295 give the same key"),
]
