"""fppo_jax.analysis.scheduling: the tune's loop trains whatever a scheduler asks, knowing none.
A race over seeds (each round a fresh seed for the trials still in, from scratch, to the full
budget: the budget spent as seeds, not updates) runs through the same loop as successive
halving: one program per round, seeds only for the contenders, recorded, resumed from its
records and reported; and a window may go on from another run's state at a setting of its
own (as population-based training copies a run)."""

import math

import numpy as np
from conftest import TINY

from fppo_jax.analysis import population as population_module
from fppo_jax.analysis.population import Population, Window, read_leaves
from fppo_jax.analysis.tune_storage import open_storage
from fppo_jax.analysis.tuning_draws import (
    draw_population,
    import_optuna,
    setting_of,
)
from fppo_jax.analysis.tuning_rungs import TaskTune
from fppo_jax.core.resolution import resolve
from fppo_jax.core.search_space import search_spaces
from fppo_jax.run.prepare import prepare

TRIALS, SEEDS = 3, (7, 8)


class SeedRace:
    """Round r trains the trials still in on seed ``SEEDS[r]`` from scratch to the end; a
    trial's score is its mean over its seeds so far; the best two go on, then the best one."""

    rounds, updates_per_call = len(SEEDS), 2

    def __init__(self, end):
        self.end = end

    def next_window(self, recorded):
        if len(recorded) == self.rounds:
            return None
        live = recorded[-1]["arms"]["ppo"]["survivors"] if recorded else range(TRIALS)
        return Window(tuple(("ppo", t, SEEDS[len(recorded)]) for t in live), 0, self.end)

    def measured(self, recorded, last, diverged):
        window = self.next_window(recorded)
        before = (
            {r["trial"]: r["seed_scores"] for r in recorded[-1]["arms"]["ppo"]["trials"]}
            if recorded
            else {}
        )
        rows = []
        for i, (_, trial, _) in enumerate(window.runs):
            seed_scores = [*before.get(trial, []), float(last[i])]
            rows.append(
                {
                    "trial": trial,
                    "score": float(np.mean(seed_scores)),
                    "seed_scores": seed_scores,
                    "diverged": bool(diverged[i]),
                }
            )
        best = sorted(rows, key=lambda r: (-r["score"], r["trial"]))
        keep = 2 if not recorded else 1
        return {"ppo": {"trials": rows, "survivors": sorted(r["trial"] for r in best[:keep])}}


class CopyBest:
    """Round 0 trains each trial to the middle; round 1 goes on from the best run's state for
    every trial, each at its own setting."""

    rounds, updates_per_call = 2, 2

    def __init__(self, end):
        self.end = end

    def next_window(self, recorded):
        runs = tuple(("ppo", t, SEEDS[0]) for t in range(TRIALS))
        if not recorded:
            return Window(runs, 0, self.end // 2)
        if len(recorded) == 2:
            return None
        rows = recorded[0]["arms"]["ppo"]["trials"]
        best = max(range(TRIALS), key=lambda i: (rows[i]["score"], -i))
        return Window(runs, self.end // 2, self.end, (best,) * TRIALS)

    def measured(self, recorded, last, diverged):
        rows = [
            {
                "trial": t,
                "score": float(last[t]),
                "seed_scores": [float(last[t])],
                "diverged": bool(diverged[t]),
            }
            for t in range(TRIALS)
        ]
        return {"ppo": {"trials": rows, "survivors": list(range(TRIALS))}}


def _task_tune(tmp_path, scheduler_of, said):
    optuna = import_optuna()
    storage = open_storage(optuna, f"sqlite:///{tmp_path / 'optuna.db'}")
    arms = [resolve("ppo")]
    drawn = draw_population(
        optuna, storage, "cartpole", arms, search_spaces(arms, None), TRIALS, "random", 0
    )
    settings = {arm: [setting_of(p) for p in trials] for arm, trials in drawn.items()}
    prepared = prepare("cartpole", TINY, (), total_steps=8 * 128, preset="paper", backend="auto")
    scheduler = scheduler_of(prepared.config.num_updates)
    population = Population(prepared, arms, settings, scheduler.updates_per_call, None, said.append)
    return TaskTune("cartpole", population, scheduler, tmp_path / "cartpole", optuna, storage)


def test_a_race_over_seeds_runs_through_the_tunes_loop(tmp_path, monkeypatch):
    compiled = []
    original = population_module.compile_program

    def counting(*args, **kwargs):
        compiled.append(args[1].shape[0])  # the runs of the program
        return original(*args, **kwargs)

    monkeypatch.setattr(population_module, "compile_program", counting)
    said = []
    tuned = _task_tune(tmp_path, SeedRace, said)
    tuned.read(join=True)
    assert tuned.train(math.inf, None) == 2 and tuned.finished
    assert compiled == [3, 2]  # one program per round, the second for the two contenders only
    first, second = tuned.scores
    contenders = first["arms"]["ppo"]["survivors"]
    assert [r["trial"] for r in second["arms"]["ppo"]["trials"]] == contenders
    assert all(len(r["seed_scores"]) == 2 for r in second["arms"]["ppo"]["trials"])
    results = tuned.results("ppo")["ppo"]
    assert results["chosen"]["trial"] == second["arms"]["ppo"]["survivors"][0]
    full = (
        tuned.population.prepared.config.num_updates
        * tuned.population.prepared.config.samples_per_update
    )
    assert results["env_steps"] == (3 + 2) * full  # the budget spent in seeds
    # Its records are all it goes on from: a new loop over them trains nothing.
    again = _task_tune(tmp_path, SeedRace, [])
    again.read(join=True)
    assert again.finished and again.scores == tuned.scores
    assert any("rung 2 of 2" in line and "= 2 runs" in line for line in said)


def test_a_window_may_go_on_from_another_runs_state_at_its_own_setting(tmp_path):
    tuned = _task_tune(tmp_path, CopyBest, [])
    tuned.read(join=True)
    tuned.train(1, None)
    rows = tuned.scores[0]["arms"]["ppo"]["trials"]
    best = max(range(TRIALS), key=lambda i: (rows[i]["score"], -i))
    saved = read_leaves(tmp_path / "cartpole" / "rung-0" / "state.npz")
    for leaf in saved:  # every run goes on from the best one's state
        assert all(np.array_equal(leaf[i], leaf[best]) for i in range(TRIALS))
    tuned.train(1, None)
    assert tuned.finished
    last = [r["score"] for r in tuned.scores[1]["arms"]["ppo"]["trials"]]
    assert len(set(last)) > 1  # the same state, trained on at settings of their own
