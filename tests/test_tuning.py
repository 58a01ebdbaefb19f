"""fppo_jax.tune: the plan first, rungs that halve in one program each, the same steps for every
arm, a resume bit for bit, a changed plan refused, and the chosen settings tested by a study
on seeds the tune never used."""

import contextlib
import io
import itertools
import json
import re
import shutil

import jax.numpy as jnp
import pytest
from conftest import TINY
from helpers import TUNE_ARMS as ARMS
from helpers import TUNE_SMALL as SMALL
from helpers import rung_scores
from own_surrogates import half_finite

import fppo_jax
from fppo_jax.analysis import population, tuning, tuning_rungs
from fppo_jax.analysis.studies import study
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.analysis.tune_design import TUNING_SEED_START
from fppo_jax.analysis.tune_files import recorded_rungs, tune_digest
from fppo_jax.analysis.tuning import default_chunk, tune
from fppo_jax.analysis.tuning_draws import import_optuna
from fppo_jax.analysis.tuning_report import across_tasks
from fppo_jax.errors import InvalidInput
from fppo_jax.stats import statistics


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

        original = population.compile_program
        patch.setattr(population, "compile_program", counting)
        said = io.StringIO()
        with contextlib.redirect_stderr(said):
            result = tune("cartpole", ARMS, output=output, **{**SMALL, "progress": True})
    return output, result, compiled, said.getvalue().splitlines()


def test_a_tune_halves_each_arm_in_one_program_per_rung(tuned):
    output, result, compiled, said = tuned
    assert result.finished
    *scores, race = rung_scores(output)
    for arm in ARMS:
        assert [len(rung["arms"][arm]["trials"]) for rung in scores] == [4, 2, 1]
        # Then the default and the finalist race on the validation seeds.
        assert [row["trial"] for row in race["arms"][arm]["trials"]][:1] == [0]
        assert len(race["arms"][arm]["trials"][0]["seed_scores"]) == 4
        # The survivors of a rung are the live trials of the next.
        for rung, following in itertools.pairwise(scores):
            assert [row["trial"] for row in following["arms"][arm]["trials"]] == rung["arms"][arm][
                "survivors"
            ]
    # On a CPU every rung and the race train in groups of one trial's 2 seeds: one program,
    # compiled once for the whole tune, which the plan records; only the first rung says it
    # compiles.
    assert compiled == [2]
    assert result.plan["settings"]["chunk"] == 2
    headers = [line for line in said if re.match(r"cartpole: rung \d of 4: trials", line)]
    assert [line.endswith("; compiling…") for line in headers] == [True, False, False, False]
    assert all(seed == TUNING_SEED_START + i for i, seed in enumerate(result.plan["seeds"]))


def test_every_arm_spends_the_planned_env_steps(tuned):
    _output, result, _, _ = tuned
    planned = result.plan["budget"]["cartpole"]["env_steps_per_arm"]
    # Halving's 2 seeds × (4 × 2 + 2 × 2 + 1 × 4) updates, then 2 entrants × 4 full runs.
    assert planned == (2 * (4 * 2 + 2 * 2 + 1 * 4) + 2 * 4 * 8) * 128
    assert [result.results["cartpole"][arm]["env_steps"] for arm in ARMS] == [planned] * 2


def test_trial_0_is_each_arms_default_and_the_shared_axes_are_the_same_points(tuned):
    output, result, _, _ = tuned
    ppo, lp = (
        import_optuna().load_study(
            study_name=f"{result.plan['storage']['studies']}/cartpole/{arm}",
            storage=f"sqlite:///{output}/optuna.db",
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
    assert 8 in ppo.best_trial.intermediate_values  # at the race, if not at the last rung


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
    whole, _, _, _ = tuned
    # Stopped after its first rung, then killed while recording its second (its survivors'
    # state written, its scores not): the rung in flight is all that is lost.
    tune("cartpole", ARMS, output=tmp_path, rungs=1, **SMALL)
    real = tuning_rungs.write_json

    def killed(path, value):
        if path.name == "scores.json" and path.parent.name == "rung-1":
            raise KeyboardInterrupt
        real(path, value)

    monkeypatch.setattr(tuning_rungs, "write_json", killed)
    with pytest.raises(KeyboardInterrupt):
        tune("cartpole", ARMS, output=tmp_path, **SMALL)
    assert (tmp_path / "cartpole/rung-1/state.npz").exists()
    monkeypatch.setattr(tuning_rungs, "write_json", real)
    result = tune("cartpole", ARMS, output=tmp_path, **SMALL)
    assert result.finished
    assert seed_scores(tmp_path) == seed_scores(whole)
    assert json.loads((tmp_path / "results.json").read_text()) == json.loads(
        (whole / "results.json").read_text()
    )


def test_a_changed_plan_is_refused_naming_the_change(tuned, tmp_path):
    output, _, _, _ = tuned
    copy = tmp_path / "tune"
    shutil.copytree(output, copy)
    with pytest.raises(InvalidInput, match="trials = 4, not 8"):
        tune("cartpole", ARMS, output=copy, **{**SMALL, "trials": 8})
    with pytest.raises(InvalidInput, match="variants"):
        tune("cartpole", ["ppo", "spo"], output=copy, **SMALL)
    with pytest.raises(InvalidInput, match=r"sampler\.seed = 0, not 1"):
        tune("cartpole", ARMS, output=copy, **{**SMALL, "sampler_seed": 1})
    # Another Optuna release is recorded, as the commit is, and not held against the tune: every
    # trial was drawn before the first rung.
    plan = json.loads((copy / "tune.json").read_text())
    plan["sampler"]["package"] = "optuna 0.0.1"
    (copy / "tune.json").write_text(json.dumps(plan))
    assert tune("cartpole", ARMS, output=copy, **SMALL).finished
    assert json.loads((copy / "tune.json").read_text())["sampler"]["package"] == "optuna 0.0.1"


def test_a_study_tests_the_chosen_settings_on_fresh_seeds_with_the_defaults_beside(tuned, tmp_path):
    output, result, _, _ = tuned
    arguments = dict(max_seeds=2, group_size=2, total_steps=8 * 128, progress=False, **TINY)
    found = study(
        "cartpole", "fppo-lp", "ppo", output=tmp_path / "study", tuned=output, **arguments
    )
    plan = found.plan["tuned"]
    assert plan["settings"]["cartpole"] == {
        arm: result.chosen("cartpole", arm) for arm in ["fppo-lp", "ppo"]
    }
    assert plan["plan_digest"] == tune_digest(output)
    # Copied elsewhere (another clone, another node), the study goes on: a tune is known by its
    # plan's digest, not where it lay; a tune of another plan is refused.
    moved = tmp_path / "moved"
    shutil.copytree(output, moved / "tune")
    shutil.copytree(tmp_path / "study", moved / "study")
    again = study(
        "cartpole", "fppo-lp", "ppo", output=moved / "study", tuned=moved / "tune", **arguments
    )
    assert again.decisions == found.decisions
    (moved / "tune/tune.json").write_text((moved / "tune/tune.json").read_text() + "\n")
    with pytest.raises(InvalidInput, match=r"planned with tuned\.plan_digest = "):
        study(
            "cartpole", "fppo-lp", "ppo", output=moved / "study", tuned=moved / "tune", **arguments
        )
    trained = found.results["cartpole"]
    assert trained.seeds == [0, 1]
    for setting in trained.settings:
        expected = result.chosen("cartpole", setting["variant"])
        assert {k: v for k, v in setting.items() if k != "variant"} == pytest.approx(expected)
    report = (tmp_path / "study/report.md").read_text()
    assert "setting a tune chose" in report
    assert "beside_defaults" not in json.loads((tmp_path / "study/decisions.json").read_text())
    with pytest.raises(InvalidInput, match="on a tune's settings: give tuned"):
        study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", with_defaults=True, **arguments)

    # The defaults beside: taken here from a study of the defaults without a tune, not trained.
    plain = study("cartpole", "fppo-lp", "ppo", output=tmp_path / "plain", **arguments)
    both = study(
        "cartpole",
        "fppo-lp",
        "ppo",
        output=tmp_path / "both",
        tuned=output,
        with_defaults=True,
        reuse=tmp_path / "plain",
        **arguments,
    )
    assert both.decisions == found.decisions  # the option adds runs, never changes a decision
    assert both.plan["with_defaults"] is True
    assert both.defaults["cartpole"].seeds == [0, 1]
    record = json.loads((tmp_path / "both/decisions.json").read_text())
    assert [
        (g.get("defaults", False), "commit" in g, sorted(g.get("reused", {})))
        for g in record["groups"]
    ] == [(False, True, []), (True, False, ["fppo-lp", "ppo"])]
    beside = record["beside_defaults"]
    assert beside["endpoint"] == "final" and beside["tested"] is False
    defaults = plain.results["cartpole"]
    for row in beside["tuned_against_default"]:
        arm = row["arm"]
        expected = statistics.compare(
            run_scores(found.results["cartpole"], arm, "final"), run_scores(defaults, arm, "final")
        )
        assert row["seeds"] == 2
        assert row["probability_of_improvement"] == pytest.approx(
            expected["probability_of_improvement"], nan_ok=True
        )
    assert [row["arm"] for row in beside["tuned_against_default"]] == ["fppo-lp", "ppo"]
    (compared,) = beside["default_against_default"]
    expected = statistics.compare(
        run_scores(defaults, "fppo-lp", "final"), run_scores(defaults, "ppo", "final")
    )
    assert compared["probability_of_improvement"] == pytest.approx(
        expected["probability_of_improvement"], nan_ok=True
    )
    report = (tmp_path / "both/report.md").read_text()
    assert "| arm | seeds | P(tuned > default) | IQM difference, tuned − default |" in report
    assert "| ppo | 2 | " in report and "not tested, outside the family" in report
    decision = found.decisions[0]["decision"]
    assert f"| fppo-lp | {decision} | 2 | " in report
    with pytest.raises(InvalidInput, match="planned with with_defaults = true, not none"):
        study(
            "cartpole",
            "fppo-lp",
            "ppo",
            output=tmp_path / "both",
            tuned=output,
            reuse=tmp_path / "plain",
            **arguments,
        )


def test_a_study_refuses_the_tunes_seeds_and_another_protocol(tuned, tmp_path):
    output, _, _, _ = tuned
    copy = tmp_path / "tune"
    shutil.copytree(output, copy)
    plan = json.loads((copy / "tune.json").read_text())
    plan["seeds"] = [1, 2]
    (copy / "tune.json").write_text(json.dumps(plan))
    arguments = dict(max_seeds=4, group_size=2, total_steps=8 * 128, progress=False, **TINY)
    with pytest.raises(InvalidInput, match=r"used seeds \[1, 2\] that this study would test on"):
        study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", tuned=copy, **arguments)
    with pytest.raises(
        InvalidInput, match=r"other protocol than this study \(num_envs: 4 in the tune, 8 in"
    ):
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


def _rung(arms):
    """A rung's scores as scores.json records them: per arm, trial → score (None: no episode
    finished; a list: diverged, with that score)."""
    return {
        "arms": {
            arm: {
                "trials": [
                    {
                        "trial": t,
                        "score": score[0] if isinstance(score, list) else score,
                        "diverged": isinstance(score, list),
                    }
                    for t, score in trials.items()
                ]
            }
            for arm, trials in arms.items()
        }
    }


def test_across_tasks_the_best_mean_normalised_score_at_the_deepest_rung_every_task_shares():
    rungs = {
        # ppo's best here is trial 1, spo's trial 1: both go on.
        "a": [
            _rung({"ppo": {0: 10.0, 1: 50.0, 2: 30.0}, "spo": {0: 0.0, 1: 100.0, 2: 20.0}}),
            _rung({"ppo": {1: 60.0}, "spo": {1: 90.0}}),
        ],
        # ppo's best here is trial 2, spo's trial 1 again.
        "b": [
            _rung(
                {"ppo": {0: -100.0, 1: -90.0, 2: -50.0}, "spo": {0: -200.0, 1: -60.0, 2: -100.0}}
            ),
            _rung({"ppo": {2: -40.0}, "spo": {1: -70.0}}),
        ],
    }
    # No trial of ppo reached the second rung on both: on the first, normalised over every
    # arm's trials per task (a: 0 … 100, b: -200 … -50), trial 2's mean (0.3 + 1.0) / 2 beats
    # trial 1's (0.5 + 0.733) / 2 and trial 0's.
    found = across_tasks(rungs, "ppo")
    assert found == {"trial": 2, "rung": 0, "normalised_score": pytest.approx(0.65)}
    # spo's trial 1 reached the second rung on both tasks: it is the one compared there.
    assert across_tasks(rungs, "spo") == {"trial": 1, "rung": 1, "normalised_score": 0.5}
    # A trial that diverged on a task reached no rung there (nor one that never scored), and
    # its score normalises nothing.
    rungs["b"][0]["arms"]["ppo"]["trials"][2]["diverged"] = True
    rungs["b"][1]["arms"]["ppo"]["trials"] = []
    found = across_tasks(rungs, "ppo")
    assert found == {
        "trial": 1,
        "rung": 0,
        "normalised_score": pytest.approx((0.5 + 110 / 140) / 2),
    }
    # A task where every trial ties counts 0 for each; ties go to the lower trial number.
    tied = {
        "a": [_rung({"ppo": {0: 5.0, 1: 7.0, 2: 7.0}})],
        "c": [_rung({"ppo": {0: 5.0, 1: 5.0, 2: 5.0}})],
    }
    assert across_tasks(tied, "ppo") == {"trial": 1, "rung": 0, "normalised_score": 0.5}
    assert (
        across_tasks({"a": rungs["a"], "c": [_rung({"ppo": {0: None, 1: [3.0]}})]}, "ppo") is None
    )


def test_a_tune_draws_the_same_trials_on_every_task(tmp_path):
    tuned = tune(["cartpole", "acrobot"], ARMS, output=tmp_path, rungs=0, **SMALL)
    studies = tuned.plan["storage"]["studies"]
    optuna = import_optuna()
    for arm in ARMS:
        drawn = [
            [
                t.params
                for t in optuna.load_study(
                    study_name=f"{studies}/{task}/{arm}",
                    storage=f"sqlite:///{tmp_path}/optuna.db",
                ).trials
            ]
            for task in ("cartpole", "acrobot")
        ]
        assert drawn[0] == drawn[1] and len(drawn[0]) == SMALL["trials"]


def test_a_study_across_tasks_takes_each_arms_trial_for_every_task(tuned, tmp_path):
    output, _, _, _ = tuned
    arguments = dict(max_seeds=2, group_size=2, total_steps=8 * 128, progress=False, **TINY)
    with pytest.raises(InvalidInput, match="tuned one task \\(cartpole\\): a setting chosen"):
        study(
            "cartpole",
            "fppo-lp",
            "ppo",
            output=tmp_path / "s",
            tuned=output,
            across_tasks=True,
            **arguments,
        )
    with pytest.raises(InvalidInput, match="on a tune's settings: give tuned"):
        study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", across_tasks=True, **arguments)
    # A second task made of the first's records: its trials' settings are the same, as a tune's
    # draws are on every task.
    copy = tmp_path / "tune"
    shutil.copytree(output, copy)
    shutil.copytree(copy / "cartpole", copy / "acrobot")
    plan = json.loads((copy / "tune.json").read_text())
    plan["tasks"].append("acrobot")
    (copy / "tune.json").write_text(json.dumps(plan))
    results = json.loads((copy / "results.json").read_text())
    results["acrobot"] = results["cartpole"]
    (copy / "results.json").write_text(json.dumps(results))
    found = study(
        "cartpole",
        "fppo-lp",
        "ppo",
        output=tmp_path / "study",
        tuned=copy,
        across_tasks=True,
        with_defaults=True,
        **arguments,
    )
    recorded = {task: recorded_rungs(copy / task) for task in ("cartpole", "acrobot")}
    trials = {arm: across_tasks(recorded, arm) for arm in ["fppo-lp", "ppo"]}
    assert found.plan["tuned"]["trials"] == trials
    assert found.plan["tuned"]["selection"].startswith("across tasks: per arm, one trial")
    for setting in found.results["cartpole"].settings:
        arm = setting.pop("variant")
        assert setting == pytest.approx(results["cartpole"][arm]["trials"][trials[arm]["trial"]])
    assert [s["variant"] for s in found.defaults["cartpole"].settings] == ["fppo-lp", "ppo"]
    assert "chosen across the tune's tasks" in (tmp_path / "study/report.md").read_text()
    with pytest.raises(InvalidInput, match=r"planned with tuned\.selection = "):
        study(
            "cartpole",
            "fppo-lp",
            "ppo",
            output=tmp_path / "study",
            tuned=copy,
            with_defaults=True,
            **arguments,
        )
    results = json.loads((copy / "results.json").read_text())
    results["cartpole"]["ppo"]["default"]["setting"]["gamma"] = 0.95
    (copy / "results.json").write_text(json.dumps(results))
    with pytest.raises(InvalidInput, match=r"tried ppo.s default on cartpole with gamma = 0\.95"):
        study(
            "cartpole",
            "fppo-lp",
            "ppo",
            output=tmp_path / "s",
            tuned=copy,
            with_defaults=True,
            **arguments,
        )
    for arms in results.values():
        for arm in arms.values():
            del arm["trials"]
    (copy / "results.json").write_text(json.dumps(results))
    with pytest.raises(InvalidInput, match="run the same tune command again"):
        study(
            "cartpole",
            "fppo-lp",
            "ppo",
            output=tmp_path / "s",
            tuned=copy,
            across_tasks=True,
            **arguments,
        )


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
        ({"chunk": 3}, "must be a multiple of the 2 seeds per trial, got 3"),
        (
            {"space": [("learning_rate", (1e-4, 1e-3))]},
            "space must be a space file's path or a mapping of names to intervals, such as .*, "
            "got \\[\\('learning_rate'",
        ),
    ],
)
def test_bad_input_is_refused_before_any_plan(tmp_path, arguments, message):
    with pytest.raises(InvalidInput, match=message):
        tune("cartpole", ARMS, output=tmp_path / "tune", **{**SMALL, **arguments})
    assert not (tmp_path / "tune").exists()


@pytest.mark.parametrize("output", [None, "", 3])
def test_an_output_that_is_no_path_is_refused_in_one_line(output):
    with pytest.raises(InvalidInput, match=f"output must be a folder's path .*, got {output!r}$"):
        tune("cartpole", ARMS, output=output, **SMALL)


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


def test_a_surrogate_not_finite_over_part_of_its_interval_stops_the_tune_naming_what_to_narrow(
    tmp_path,
):
    # Tried at a drawn point before it trains, it cannot fail that trial alone: it stops the
    # tune at the rung, saying which interval to narrow.
    with pytest.raises(
        InvalidInput,
        match=r"^surrogate 'half-finite' has a value that is not finite \(nan\) .* beta = "
        r"0\.[5-9]\d*: .* narrow the interval of beta or epsilon to where it is finite, in a "
        r"space file, --space, and tune into a new output\)$",
    ):
        tune("cartpole", ["ppo", half_finite], output=tmp_path, **SMALL)


def test_the_command_line_plans_tunes_and_refuses_in_one_line(tuned, tmp_path, capsys):
    from fppo_jax.cli import main

    flags = ["tune", "--variants", "ppo,fppo-lp", "--tasks", "cartpole", "--trials", "4"]
    flags += ["--eta", "2", "--steps", "1024", "--num-envs", "4", "--num-steps", "32"]
    flags += ["--minibatches", "4", "--epochs", "2", "--quiet", "--score", "train"]
    flags += ["--finalists", "1", "--validation-seeds", "4", "--race-level", "0.1"]
    assert main([*flags, "--output", str(tmp_path / "a"), "--rungs", "0"]) == 0
    assert "the same command goes on" in capsys.readouterr().out
    plan = json.loads((tmp_path / "a/tune.json").read_text())
    output, _, _, _ = tuned
    recorded = json.loads((output / "tune.json").read_text())
    # The same plan, but for its run settings' spelling and its studies' names in its storage.
    assert {k: v for k, v in plan.items() if k not in ("settings", "storage")} == {
        k: v for k, v in recorded.items() if k not in ("settings", "storage")
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


def test_a_study_on_a_tune_takes_its_steps_and_refuses_others_by_name(tuned, tmp_path, capsys):
    output, _, _, _ = tuned
    arguments = dict(max_seeds=2, group_size=2, groups=0, progress=False, **TINY)
    found = study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", tuned=output, **arguments)
    assert found.plan["settings"]["total_steps"] == 8 * 128  # the tune's, not the task's
    with pytest.raises(InvalidInput, match=r"total_steps = 1024 \(--steps\) per run, not 2048"):
        study("cartpole", "fppo-lp", output=tmp_path / "t", tuned=output, total_steps=2048)
    from fppo_jax.cli import main

    flags = ["study", "--tuned", str(output), "--candidates", "fppo-lp", "--tasks", "cartpole"]
    assert main([*flags, "--steps", "2048", "--output", str(tmp_path / "u")]) == 2
    assert capsys.readouterr().err.startswith(
        f"fppo-jax: error: the tune in {output} trained total_steps = 1024 (--steps) per run"
    )


class _Task:
    """A prepared task as :func:`default_chunk` sees it: its environment."""

    def __init__(self, on_host):
        self.environment = type("Env", (), {"resets_itself": on_host})()


def test_the_default_chunk_is_one_trials_seeds_on_a_cpu_for_tasks_stepped_in_jax(
    tmp_path, monkeypatch
):
    assert default_chunk(tmp_path, {"a": _Task(False), "b": _Task(False)}, 3) == 3
    # Environments on the host (native MuJoCo) and accelerators gain from a rung's runs in one
    # wide call.
    assert default_chunk(tmp_path, {"a": _Task(False), "b": _Task(True)}, 3) is None
    monkeypatch.setattr(tuning.jax, "default_backend", lambda: "gpu")
    assert default_chunk(tmp_path, {"a": _Task(False)}, 3) is None


@pytest.mark.parametrize(("settings", "chunk"), [({"chunk": 8}, 8), ({}, None)])
def test_a_tune_planned_before_goes_on_in_the_groups_its_plan_records(tmp_path, settings, chunk):
    (tmp_path / "tune.json").write_text(json.dumps({"settings": {"preset": "paper", **settings}}))
    assert default_chunk(tmp_path, {"a": _Task(False)}, 2) == chunk


def test_a_tune_planned_without_a_chunk_trains_each_rung_whole_in_any_split(
    tmp_path, monkeypatch, capsys
):
    output = tmp_path / "tune"
    tune("cartpole", ARMS, output=output, rungs=0, **SMALL)
    plan = json.loads((output / "tune.json").read_text())
    del plan["settings"]["chunk"]  # as a tune planned before the default chunk recorded it
    (output / "tune.json").write_text(json.dumps(plan))
    compiled = []
    original = population.compile_program
    monkeypatch.setattr(
        population,
        "compile_program",
        lambda *a, **k: compiled.append(a[1].shape[0]) or original(*a, **k),
    )
    small = {**SMALL, "progress": True}
    tune("cartpole", ARMS, output=output, part=(2, 2), **small)  # one group: the first part's
    assert "nothing to train, the rung's 16 runs make 1 group, fewer than the parts" in (
        capsys.readouterr().err
    )
    tune("cartpole", ARMS, output=output, part=(1, 2), **SMALL)
    assert compiled == [2 * 4 * 2]  # the first rung's runs, every arm's, in one call
    joined = tune("cartpole", ARMS, output=output, rungs=0, **SMALL)
    assert len(joined.rungs["cartpole"]) == 1
