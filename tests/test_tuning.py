"""fppo_jax.tune: the plan first, rungs that halve in one program each, the same steps for every
arm, a resume bit for bit, a changed plan refused, and the chosen settings tested by a study
on seeds the tune never used."""

import itertools
import json
import shutil

import jax.numpy as jnp
import numpy as np
import pytest
from conftest import TINY

import fppo_jax
from fppo_jax.analysis import tuning
from fppo_jax.analysis.studies import study
from fppo_jax.analysis.tuning import TUNING_SEED_START, schedule, tune
from fppo_jax.errors import InvalidInput

# Four trials per arm halved by 2 over 8 updates: rungs of 4, 2 and 1 trials ending at updates
# 2, 4 and 8.
SMALL = dict(trials=4, eta=2, seeds=2, total_steps=8 * 128, progress=False, **TINY)
ARMS = ["ppo", "fppo-lp"]


def rung_scores(directory, task="cartpole"):
    rungs = sorted((directory / task).glob("rung-*/scores.json"))
    return [json.loads(path.read_text()) for path in rungs]


def seed_scores(directory):
    return [
        {arm: [row["seed_scores"] for row in rung["arms"][arm]["trials"]] for arm in ARMS}
        for rung in rung_scores(directory)
    ]


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    """A whole tune, counting the programs it compiles."""
    output = tmp_path_factory.mktemp("tune")
    compiled = []
    with pytest.MonkeyPatch.context() as patch:

        def counting(*args, **kwargs):
            compiled.append(args[1].shape[0])  # the runs of the program
            return original(*args, **kwargs)

        original = tuning.compile_program
        patch.setattr(tuning, "compile_program", counting)
        result = tune("cartpole", ARMS, output=output, **SMALL)
    return output, result, compiled


def test_schedule_halves_the_trials_and_ends_at_the_full_budget():
    rungs = schedule(27, 3, 81)
    assert rungs.trials == (27, 9, 3, 1)
    assert rungs.ends == (3, 9, 27, 81)
    assert schedule(10, 3, 100).trials == (10, 3, 1)
    assert schedule(10, 3, 100).ends == (11, 33, 100)
    # Every trial trains the first rung; the survivors each rung's further updates.
    assert rungs.updates_per_arm(seeds=2) == 2 * (27 * 3 + 9 * 6 + 3 * 18 + 1 * 54)
    assert schedule(1, 3, 5).ends == (5,)
    # Progress between calls: the first rung (3 updates here, 54 on MuJoCo) in whole calls.
    assert rungs.updates_per_call == 1
    assert schedule(9, 3, 488).updates_per_call == 3
    with pytest.raises(InvalidInput, match="too short for 4 rungs"):
        schedule(27, 3, 20)


def test_a_tune_halves_each_arm_in_one_program_per_rung(tuned):
    output, result, compiled = tuned
    assert result.finished
    scores = rung_scores(output)
    for arm in ARMS:
        assert [len(rung["arms"][arm]["trials"]) for rung in scores] == [4, 2, 1]
        # The survivors of a rung are the live trials of the next.
        for rung, following in itertools.pairwise(scores):
            assert [row["trial"] for row in following["arms"][arm]["trials"]] == rung["arms"][arm][
                "survivors"
            ]
    # Every arm's live trials × seeds in one program per rung, none compiled twice.
    assert compiled == [2 * 4 * 2, 2 * 2 * 2, 2 * 1 * 2]
    assert all(seed == TUNING_SEED_START + i for i, seed in enumerate(result.plan["seeds"]))


def test_every_arm_spends_the_planned_env_steps(tuned):
    _output, result, _ = tuned
    planned = result.plan["budget"]["cartpole"]["env_steps_per_arm"]
    assert planned == 2 * (4 * 2 + 2 * 2 + 1 * 4) * 128
    assert [result.results["cartpole"][arm]["env_steps"] for arm in ARMS] == [planned] * 2


def test_trial_0_is_each_arms_default_and_the_shared_axes_are_the_same_points(tuned):
    output, result, _ = tuned
    ppo, lp = (
        tuning._optuna().load_study(
            study_name=f"cartpole/{arm}", storage=f"sqlite:///{output}/optuna.db"
        )
        for arm in ARMS
    )
    first = ppo.trials[0].params
    assert first == {
        "learning_rate": 3e-4,
        "1-gamma": pytest.approx(0.01),
        "gae_lambda": 0.95,
        "epsilon": 0.2,
        "entropy_coef": 0.0,
        "max_grad_norm": 0.5,
        "value_coef": 0.5,
    }
    assert lp.trials[0].params["alpha"] == 1.3  # Table 2 on CartPole
    for a, b in zip(ppo.trials, lp.trials, strict=True):
        assert {k: v for k, v in b.params.items() if k != "alpha"} == a.params
    assert len({t.params["learning_rate"] for t in ppo.trials}) == 4
    # Optuna holds each trial's score at each rung it reached, and how it ended.
    states = [t.state.name for t in ppo.trials]
    assert states.count("COMPLETE") == 1 and states.count("PRUNED") == 3
    chosen = result.results["cartpole"]["ppo"]["chosen"]
    assert ppo.best_trial.number == chosen["trial"]
    assert ppo.best_trial.value == chosen["score"]
    assert sorted(ppo.best_trial.intermediate_values) == [2, 4, 8]


def test_the_plan_is_written_before_any_run(tmp_path):
    result = tune("cartpole", ARMS, output=tmp_path, rungs=0, **SMALL)
    assert not result.finished
    plan = json.loads((tmp_path / "tune.json").read_text())
    assert plan["variants"] == ARMS and plan["trials"] == 4 and plan["eta"] == 2
    assert plan["budget"]["cartpole"]["rungs"][-1]["env_steps_per_run"] == 8 * 128
    assert plan["space"]["fppo-lp"]["alpha"] == {"low": 1.0, "high": 2.0, "scale": "linear"}
    assert plan["sampler"]["name"] == "qmc" and "commit" in plan
    assert not list(tmp_path.glob("cartpole/rung-*"))


def test_a_stopped_or_killed_tune_goes_on_bit_for_bit(tuned, tmp_path, monkeypatch):
    whole, _, _ = tuned
    # Stopped after its first rung, then killed while recording its second (its survivors'
    # state written, its scores not): the rung in flight is all that is lost.
    tune("cartpole", ARMS, output=tmp_path, rungs=1, **SMALL)
    real = tuning.write_json

    def killed(path, value):
        if path.name == "scores.json" and path.parent.name == "rung-1":
            raise KeyboardInterrupt
        real(path, value)

    monkeypatch.setattr(tuning, "write_json", killed)
    with pytest.raises(KeyboardInterrupt):
        tune("cartpole", ARMS, output=tmp_path, **SMALL)
    assert (tmp_path / "cartpole/rung-1/state.npz").exists()
    monkeypatch.setattr(tuning, "write_json", real)
    result = tune("cartpole", ARMS, output=tmp_path, **SMALL)
    assert result.finished
    assert seed_scores(tmp_path) == seed_scores(whole)
    assert json.loads((tmp_path / "results.json").read_text()) == json.loads(
        (whole / "results.json").read_text()
    )


def test_a_changed_plan_is_refused_naming_the_change(tuned, tmp_path):
    output, _, _ = tuned
    copy = tmp_path / "tune"
    shutil.copytree(output, copy)
    with pytest.raises(InvalidInput, match="trials = 4, not 8"):
        tune("cartpole", ARMS, output=copy, **{**SMALL, "trials": 8})
    with pytest.raises(InvalidInput, match="variants"):
        tune("cartpole", ["ppo", "spo"], output=copy, **SMALL)


def test_a_study_tests_the_chosen_settings_on_fresh_seeds(tuned, tmp_path):
    output, result, _ = tuned
    found = study(
        "cartpole",
        "fppo-lp",
        "ppo",
        output=tmp_path / "study",
        tuned=output,
        max_seeds=2,
        group_size=2,
        total_steps=8 * 128,
        progress=False,
        **TINY,
    )
    plan = found.plan["tuned"]
    assert plan["settings"]["cartpole"] == {
        arm: result.chosen("cartpole", arm) for arm in ["fppo-lp", "ppo"]
    }
    assert plan["plan_digest"] == tuning.plan_digest(output)
    trained = found.results["cartpole"]
    assert trained.seeds == [0, 1]
    for setting in trained.settings:
        expected = result.chosen("cartpole", setting["variant"])
        assert {k: v for k, v in setting.items() if k != "variant"} == pytest.approx(expected)
    report = (tmp_path / "study/report.md").read_text()
    assert "setting a tune chose" in report


def test_a_study_refuses_the_tunes_seeds_and_another_protocol(tuned, tmp_path):
    output, _, _ = tuned
    copy = tmp_path / "tune"
    shutil.copytree(output, copy)
    plan = json.loads((copy / "tune.json").read_text())
    plan["seeds"] = [1, 2]
    (copy / "tune.json").write_text(json.dumps(plan))
    arguments = dict(max_seeds=4, group_size=2, total_steps=8 * 128, progress=False, **TINY)
    with pytest.raises(InvalidInput, match=r"used seeds \[1, 2\] that this study would test on"):
        study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", tuned=copy, **arguments)
    with pytest.raises(InvalidInput, match="num_envs = 4"):
        study(
            "cartpole",
            "fppo-lp",
            "ppo",
            output=tmp_path / "s",
            tuned=output,
            **{**arguments, "num_envs": 8},
        )
    with pytest.raises(InvalidInput, match="did not tune spo"):
        study("cartpole", "spo", "ppo", output=tmp_path / "s", tuned=output, **arguments)
    with pytest.raises(InvalidInput, match="learning_rate cannot be given"):
        study(
            "cartpole",
            "fppo-lp",
            "ppo",
            output=tmp_path / "s",
            tuned=output,
            learning_rate=1e-3,
            **arguments,
        )


def test_a_tune_not_finished_is_no_source_of_settings(tmp_path):
    tune("cartpole", ARMS, output=tmp_path / "tune", rungs=0, **SMALL)
    with pytest.raises(InvalidInput, match="not finished"):
        study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", tuned=tmp_path / "tune")


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"eta": 1}, "eta .* at least 2"),
        ({"trials": 0}, "trials must be a positive integer"),
        ({"sampler": "tpe"}, "sampler must be one of qmc, random"),
        ({"learning_rate": 1e-3}, "not learning_rate: the hyperparameters are its search space"),
        (
            {"space": {"gamma": (0.9, 1.5)}},
            "of gamma leaves its range: gamma must be in \\(0, 1\\]",
        ),
        ({"space": {"learning_rate": (0, 1e-3, "log")}}, "log scale needs low > 0"),
        ({"space": {"momentum": (0, 1)}}, "no axis 'momentum'"),
        ({"space": {"fppo-lp": {"alpha": (0.5, 1.5)}}}, "of alpha leaves its range"),
        ({"space": {"fppo-lp": {"k": (0, 1)}}}, "fppo-lp 'k', which it does not take"),
        ({"total_steps": 128}, "too short for 3 rungs"),
        ({"seeds": [0, 0]}, "seeds must be distinct"),
        ({"sampler_seed": -1}, r"sampler_seed must be an integer in \[0, 2\*\*32\)"),
        ({"part": (0, 2), "chunk": 2}, r"part must be the K-th of N parts, .* got \(0, 2\)"),
        ({"part": (3, 2), "chunk": 2}, r"part must be the K-th of N parts, .* got \(3, 2\)"),
        ({"part": "x", "chunk": 2}, "part must be the K-th of N parts, 1 <= K <= N, got 'x'"),
        ({"part": (1, 2)}, "part 1 of 2 needs chunk"),
        ({"chunk": 3}, "must be a multiple of the 2 seeds per trial, got 3"),
    ],
)
def test_bad_input_is_refused_before_any_plan(tmp_path, arguments, message):
    with pytest.raises(InvalidInput, match=message):
        tune("cartpole", ARMS, output=tmp_path / "tune", **{**SMALL, **arguments})
    assert not (tmp_path / "tune").exists()


# Runs per compiled call of the split tunes: 3 trials × 2 seeds. Rung 0's 16 runs train in
# groups of 6, 6 and 4 (filled up to 6), rung 1's 8 in groups of 6 and 2, rung 2's 4 in one.
CHUNK = 6


def split_tune(output, parts, **arguments):
    """The tune of SMALL in groups of CHUNK runs split into `parts`, rung by rung: each part,
    then the join (which records the rung and trains none)."""
    arguments = {**SMALL, "chunk": CHUNK, **arguments}
    while True:
        for k in range(1, parts + 1):
            tune("cartpole", ARMS, output=output, part=(k, parts), **arguments)
        result = tune("cartpole", ARMS, output=output, rungs=0, **arguments)
        if result.finished:
            return result


def optuna_trials(directory):
    return {
        arm: [
            (t.number, t.state, t.value, t.intermediate_values, t.params)
            for t in tuning._optuna()
            .load_study(study_name=f"cartpole/{arm}", storage=f"sqlite:///{directory}/optuna.db")
            .trials
        ]
        for arm in ARMS
    }


def test_a_tune_split_into_parts_joins_into_the_unsplit_tune_bit_for_bit(tmp_path, capsys):
    whole = tune("cartpole", ARMS, output=tmp_path / "whole", chunk=CHUNK, **SMALL)
    split = split_tune(tmp_path / "split", 3, progress=True)
    assert split.finished
    # Every run's score, every trial's mean and the survivors, as the unsplit tune's.
    assert [rung["arms"] for rung in rung_scores(tmp_path / "split")] == [
        rung["arms"] for rung in rung_scores(tmp_path / "whole")
    ]
    for rung in (0, 1):  # the survivors' state, which the next rung goes on from
        with (
            np.load(tmp_path / f"whole/cartpole/rung-{rung}/state.npz") as a,
            np.load(tmp_path / f"split/cartpole/rung-{rung}/state.npz") as b,
        ):
            assert a.files == b.files
            assert all(np.array_equal(a[name], b[name], equal_nan=True) for name in a.files)
    assert split.results == whole.results
    assert {arm: split.chosen("cartpole", arm) for arm in ARMS} == {
        arm: whole.chosen("cartpole", arm) for arm in ARMS
    }
    assert optuna_trials(tmp_path / "split") == optuna_trials(tmp_path / "whole")
    # Rung 1's 8 runs make 2 groups and rung 2's 4 one: the parts past them train nothing.
    shares = [sorted(p.name for p in rung.glob("part-*")) for rung in _rungs(tmp_path / "split")]
    assert shares == [["part-1", "part-2", "part-3"], ["part-1", "part-2"], ["part-1"]]
    said = capsys.readouterr().err
    assert "cartpole: rung 2 of 3, part 3 of 3: nothing to train, the rung's 8 runs make 2" in said


def _rungs(directory):
    return sorted((directory / "cartpole").glob("rung-*"))


def test_a_missing_part_is_refused_by_name_and_a_recorded_one_not_trained_again(
    tmp_path, monkeypatch
):
    arguments = {**SMALL, "chunk": CHUNK}
    tune("cartpole", ARMS, output=tmp_path, part=(1, 2), **arguments)
    share = tmp_path / "cartpole/rung-0/part-1/scores.json"
    recorded = share.read_text()
    # Only the join tells Optuna a rung's scores: a share writes nothing there.
    assert all(not trial[3] for trials in optuna_trials(tmp_path).values() for trial in trials)

    def compiled(*args, **kwargs):
        raise AssertionError("a recorded part was trained again")

    with monkeypatch.context() as patch:
        patch.setattr(tuning, "compile_program", compiled)
        assert not tune("cartpole", ARMS, output=tmp_path, part=(1, 2), **arguments).finished
    assert share.read_text() == recorded
    with pytest.raises(
        InvalidInput,
        match=r"cartpole: rung 1 is split into 2 parts and part 2 is missing .* --part 2/2",
    ):
        tune("cartpole", ARMS, output=tmp_path, **arguments)
    assert not (tmp_path / "cartpole/rung-0/scores.json").exists()
    # The join is the tune of its plan: another chunk is refused, naming it.
    with pytest.raises(InvalidInput, match="chunk = 6, not 4"):
        tune("cartpole", ARMS, output=tmp_path, **{**arguments, "chunk": 4})


def test_a_storage_that_cannot_be_opened_is_one_error(tmp_path):
    with pytest.raises(InvalidInput, match="cannot open Optuna's storage nosuch://here"):
        tune("cartpole", ARMS, output=tmp_path, storage="nosuch://here", **SMALL)


def c_scaled(ratio, advantage, c):
    return jnp.minimum(ratio * advantage, jnp.clip(ratio, 0.8, 1.2) * advantage) * c


def test_a_surrogate_without_a_search_interval_is_refused_by_name(tmp_path):
    mine = fppo_jax.surrogate("c-scaled", c_scaled, c=1.0)
    with pytest.raises(InvalidInput, match="c-scaled has no search interval for c"):
        tune("cartpole", ["ppo", mine], output=tmp_path, **SMALL)
    searched = fppo_jax.surrogate("c-scaled", c_scaled, c=1.0, search={"c": (0.5, 2.0, "log")})
    tune("cartpole", ["ppo", searched], output=tmp_path, rungs=0, **SMALL)
    plan = json.loads((tmp_path / "tune.json").read_text())
    assert plan["space"]["c-scaled"]["c"] == {"low": 0.5, "high": 2.0, "scale": "log"}
    with pytest.raises(InvalidInput, match="search names 'd', which it does not take"):
        fppo_jax.surrogate("c-scaled", c_scaled, c=1.0, search={"d": (0.5, 2.0)})


def test_a_trial_that_diverges_scores_below_every_other_and_stops(tmp_path):
    # Learning rates up to 1e30: the largest drawn make the parameters infinite at once.
    space = {"learning_rate": (1e-4, 1e30, "log")}
    result = tune("cartpole", ARMS, output=tmp_path, space=space, **SMALL)  # the shapes above
    assert result.finished
    first = rung_scores(tmp_path)[0]["arms"]["ppo"]
    diverged = [row["trial"] for row in first["trials"] if row["diverged"]]
    assert diverged and 0 not in diverged
    assert not set(diverged) & set(first["survivors"])
    found = result.results["cartpole"]["ppo"]
    assert found["diverged_trials"] == diverged
    assert found["chosen"]["trial"] not in diverged
    studied = tuning._optuna().load_study(
        study_name="cartpole/ppo", storage=f"sqlite:///{tmp_path}/optuna.db"
    )
    assert [t.number for t in studied.trials if t.state.name == "FAIL"] == diverged
    assert "| ppo | " in (tmp_path / "report.md").read_text()


def test_the_command_line_plans_tunes_and_refuses_in_one_line(tuned, tmp_path, capsys):
    from fppo_jax.cli import main

    flags = ["tune", "--variants", "ppo,fppo-lp", "--tasks", "cartpole", "--trials", "4"]
    flags += ["--eta", "2", "--steps", "1024", "--num-envs", "4", "--num-steps", "32"]
    flags += ["--minibatches", "4", "--epochs", "2", "--quiet"]
    assert main([*flags, "--output", str(tmp_path / "a"), "--rungs", "0"]) == 0
    assert "the same command goes on" in capsys.readouterr().out
    plan = json.loads((tmp_path / "a/tune.json").read_text())
    output, _, _ = tuned
    recorded = json.loads((output / "tune.json").read_text())
    assert {k: v for k, v in plan.items() if k != "settings"} == {
        k: v for k, v in recorded.items() if k != "settings"
    }
    assert main([*flags, "--output", str(tmp_path / "b"), "--eta", "1"]) == 2
    assert capsys.readouterr().err.strip() == (
        "fppo-jax: error: eta (the halving rate) must be an integer of at least 2, got 1"
    )
    for part in ("0/2", "3/2", "x"):
        with pytest.raises(SystemExit):
            main([*flags, "--output", str(tmp_path / "c"), "--chunk", "2", "--part", part])
        said = capsys.readouterr().err
        assert "argument --part: " in said and f"got '{part}'" in said
    assert not (tmp_path / "c").exists()
