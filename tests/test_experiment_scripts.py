"""experiments/: what the scripts advise when they refuse, and their helpers on every space."""

import argparse
import datetime
import importlib
import json
import shutil
import subprocess
import sys
import types
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from helpers import run_script

from fppo_jax import SweepResult

EXPERIMENTS = Path(__file__).resolve().parent.parent / "experiments"


def test_table1_classic_advises_its_own_flags_when_a_result_is_recorded(tmp_path):
    recorded = tmp_path / "table.md"
    recorded.write_text("recorded\n")
    done = run_script(
        EXPERIMENTS / "paper" / "table1_classic.py", "--output", str(recorded), cwd=EXPERIMENTS
    )
    assert done.returncode != 0 and "is already recorded" in done.stderr
    assert "--output FILE and --curves DIR to record elsewhere" in done.stderr
    assert "--results" not in done.stderr
    assert recorded.read_text() == "recorded\n"


def test_bench_gymnasium_draws_random_actions_of_discrete_and_box_spaces(monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))  # the scripts import their common.py
    monkeypatch.syspath_prepend(str(EXPERIMENTS / "benchmarks"))
    bench_gymnasium = importlib.import_module("bench_gymnasium")
    steps = 8 * bench_gymnasium.NUM_ENVS
    discrete = bench_gymnasium.random_actions(gymnasium.spaces.Discrete(3, start=-1), steps)
    assert discrete.shape == (8, bench_gymnasium.NUM_ENVS)
    assert set(np.unique(discrete)) == {-1, 0, 1}
    box = gymnasium.spaces.Box(-2.0, 2.0, (2,), np.float32)
    actions = bench_gymnasium.random_actions(box, steps)
    assert actions.shape == (8, bench_gymnasium.NUM_ENVS, 2) and actions.dtype == np.float32
    assert (np.abs(actions) <= 2).all()
    env = gymnasium.make("CartPole-v1")
    env.reset(seed=0)
    for action in bench_gymnasium.random_actions(env.action_space, steps)[:, 0]:
        env.step(action)  # the actions a Discrete environment takes
    assert bench_gymnasium.gymnasium_alone("CartPole-v1", steps) > 0


def _planned_verdict(*args):
    script = EXPERIMENTS / "studies" / "planned_verdict.py"
    return run_script(script, *map(str, args), cwd=EXPERIMENTS)


def test_a_planned_verdict_waits_for_every_comparison_naming_what_is_missing(tmp_path):
    report = tmp_path / "verdict.md"
    done = _planned_verdict("plans/spo-dpo.json", "--results", tmp_path, "--output", report)
    assert done.returncode == 1 and not report.exists()
    assert "no verdict yet" in done.stderr
    assert "cartpole: ppo 0 of 50, spo 0 of 50, dpo 0 of 50 seeds" in done.stderr
    assert "ant: ppo 0 of 20, spo 0 of 20, dpo 0 of 20 seeds" in done.stderr


def test_a_planned_verdict_tests_the_family_on_the_recorded_parts(tmp_path):
    plan = json.loads((EXPERIMENTS / "plans" / "spo-dpo.json").read_text())
    plan["tasks"] = ["cartpole", "reacher"]  # recorded in full
    (tmp_path / "two.json").write_text(json.dumps(plan))
    report = tmp_path / "verdict.md"
    done = _planned_verdict(tmp_path / "two.json", "--output", report)
    assert done.returncode == 0, done.stderr
    rows = [line.split(" | ") for line in report.read_text().splitlines()]
    rows = [row for row in rows if len(row) > 2 and row[1] == "spo"]
    assert [row[0] for row in rows] == ["| cartpole", "| reacher"]
    holm = [float(row[6]) for row in rows]
    raw = [float(row[5]) for row in rows]
    assert all(h >= p for h, p in zip(holm, raw, strict=True))  # adjusted over the family


def test_the_re_decided_verdicts_keep_each_original_family_at_its_level(monkeypatch):
    # Each family of plans/redecided.json is one study per seed schedule, at its share of 0.05:
    # Holm's first step is 0.05 over the whole family in each, as over the family at once.
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    monkeypatch.syspath_prepend(str(EXPERIMENTS / "studies"))
    redecided = importlib.import_module("redecided")
    plan = json.loads((EXPERIMENTS / "plans" / "redecided.json").read_text())
    studies = redecided.studies_of(plan)
    assert [s["name"] for s in studies] == [
        "fppo-paper-mujoco",
        "fppo-paper-classic",
        "fppo-unnormalised-classic",
        "spo-dpo-mujoco",
        "spo-dpo-classic",
    ]
    for family, spec in plan["comparisons"].items():
        members = [s for s in studies if s["family"] == family]
        assert sum(s["level"] for s in members) == pytest.approx(redecided.LEVEL)
        for study in members:
            first = study["level"] / study["comparisons"]
            assert first == pytest.approx(redecided.LEVEL / spec["count"])
    # 20 seeds cannot decide equivalent within ±0.2, as the plan says; 50 can.
    unreachable = redecided.unreachable(studies, plan["margin"])
    assert [line.split(":")[0] for line in unreachable] == [
        "- fppo-paper-mujoco",
        "- spo-dpo-mujoco",
    ]


def test_the_dose_response_names_the_seed_and_update_where_a_control_parts(monkeypatch):
    # Recorded parts: Hopper's seed 6, where the controls train as PPO throughout, and
    # Walker2d's seed 5, where both part from it at one update.
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    monkeypatch.syspath_prepend(str(EXPERIMENTS / "studies"))
    checks = importlib.import_module("_dose_controls")  # checks.py's controls
    plan = json.loads((EXPERIMENTS / "plans" / "dose-response.json").read_text())
    parts = EXPERIMENTS / "results" / "dose_response"
    hopper = SweepResult.read(parts / "hopper" / "paper" / "seeds-6-6_dose-response")
    walker = SweepResult.read(parts / "walker2d" / "paper" / "seeds-5-5_dose-response")
    assert checks.controls(hopper, None, plan)[:2] == [
        "- fppo-lp at α = 1: identical to the sweep's PPO run on every recorded metric in 1 of 1 "
        "seeds",
        "- fppo-qp at k = 0: identical to the sweep's PPO run on every recorded metric in 1 of 1 "
        "seeds",
    ]
    parted = checks.controls(walker, None, plan)[:2]
    assert all(line.endswith("in 0 of 1 seeds; apart: seed 5 from update 126") for line in parted)
    ppo_index = checks.setting_index(walker, "ppo", None, None)
    ppo = walker.metrics["negative_fraction_after"][checks.by_seed(walker, ppo_index)[5]]
    index = checks.setting_index(walker, "fppo-lp", "alpha", 1.0)
    control = walker.metrics["negative_fraction_after"][checks.by_seed(walker, index)[5]]
    np.testing.assert_array_equal(control[:125], ppo[:125])
    assert control[125] != ppo[125]


def test_a_result_records_the_commit_it_was_made_at(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    common = importlib.import_module("common")
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=EXPERIMENTS, capture_output=True, text=True, check=True
    ).stdout.strip()
    assert common.STARTED_AT.split(" ")[0] == head
    command = next(line for line in common.header("a result") if line.startswith("- Command: "))
    assert command.endswith(f", at {common.STARTED_AT}")
    common.write_run_record(tmp_path, 1.0, protocol="paper")
    assert common.read_run_record(tmp_path)["commit"] == common.STARTED_AT


def test_the_results_index_is_current_and_reads_what_a_result_records(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    common = importlib.import_module("common")
    results_index = importlib.import_module("results_index")
    assert results_index.INDEX.read_text() == results_index.index(), (
        "experiments/results/README.md is not current: run python experiments/results_index.py"
    )
    record = tmp_path / "result.md"
    common.write_result(record, [*common.header("A result"), "", "| a | b |"])
    about = results_index.described(record)
    assert about["title"] == "A result"
    assert about["machine"] == common.machine().split(";")[0]
    assert about["date"] == str(datetime.date.today())
    assert about["command"].startswith("`python experiments/")
    assert about["commit"] == common.STARTED_AT[:12] + common.STARTED_AT[40:]


def test_the_results_index_says_where_a_moved_script_is_now(monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    results_index = importlib.import_module("results_index")
    moved = "`python experiments/bench_sweep.py --force`"
    assert results_index.now_at(moved) == "experiments/benchmarks/bench_sweep.py"
    assert results_index.now_at("`python experiments/results_index.py`") is None  # in place
    assert results_index.now_at("`python experiments/no_such_script.py`") is None
    assert results_index.now_at("`fppo-jax study --reuse experiments/results/study`") is None
    row = next(line for line in results_index.index().splitlines() if "(bench_sweep.md)" in line)
    assert "(now `experiments/benchmarks/bench_sweep.py`)" in row


FOLDERS = ("paper", "studies", "benchmarks", "profiles")


@pytest.mark.parametrize("folder", FOLDERS)
def test_a_folder_s_entry_point_lists_each_of_its_scripts(folder):
    done = run_script(EXPERIMENTS / folder, cwd=EXPERIMENTS)
    assert done.returncode == 0, done.stdout + done.stderr
    listed = [line for line in done.stdout.splitlines() if line.startswith("python ")]
    scripts = sorted((EXPERIMENTS / folder).glob("[!_]*.py"))
    assert listed == [f"python experiments/{folder}/{script.name}" for script in scripts]


def test_a_folder_s_entry_point_refuses_a_script_without_its_smoke_run(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    common = importlib.import_module("common")
    for name in ("first.py", "new.py"):
        (tmp_path / name).write_text('"""A script."""\n')
    monkeypatch.setattr(sys, "argv", ["folder"])
    with pytest.raises(SystemExit, match=r"does not name the folder's scripts: \['new.py'\]"):
        common.folder_entry_point("A folder.", tmp_path, {"first.py": ""})


@pytest.mark.slow
@pytest.mark.parametrize("folder", FOLDERS)
def test_every_script_of_a_folder_runs_tiny_into_a_temporary_directory(folder):
    before = sorted(path.stat().st_mtime_ns for path in (EXPERIMENTS / "results").rglob("*"))
    done = subprocess.run(
        [sys.executable, str(EXPERIMENTS / folder), "--smoke"], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stdout + done.stderr
    ran = [line for line in done.stdout.splitlines() if line.startswith(f"{folder}/")]
    assert len(ran) == len(list((EXPERIMENTS / folder).glob("[!_]*.py"))), done.stdout
    after = sorted(path.stat().st_mtime_ns for path in (EXPERIMENTS / "results").rglob("*"))
    assert after == before  # nothing recorded was written


def test_an_interval_is_at_the_edge_only_within_its_bounds_monte_carlo_error(monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    edges = importlib.import_module("edges")
    seeds = []

    def draw(seed):  # an upper bound that moves by 0.03 with the seed
        seeds.append(seed)
        return (0.3, 0.1, 0.51 + 0.03 * (seed % 2))

    at_edge = edges.edge((0.3, 0.1, 0.51), draw, 0.5)
    assert at_edge is not None and at_edge.bound == "upper"
    assert (at_edge.low, at_edge.high) == (0.51, 0.54) and seeds == list(range(1, 20))
    assert edges.outcome((0.3, 0.1, 0.51), at_edge) == "at the edge"
    assert "upper bound runs 0.510 to 0.540 over 20 resampling seeds" in at_edge.text()
    assert edges.edge((0.3, 0.1, 0.6), draw, 0.5) is None  # clears it by more than 0.03
    seeds.clear()
    assert edges.edge((0.2, 0.1, 0.3), draw, 0.5) is None and not seeds  # far: not drawn again
    assert edges.edge((0.5, 0.5, 0.5), lambda seed: (0.5, 0.5, 0.5), 0.5) is None  # all tied
    assert edges.outcome((0.3, 0.1, 0.45)) == "worse"


def test_the_plan_converter_names_the_rule_by_id_and_changes_nothing_else(tmp_path):
    """A study recorded when its rule's words named their module, or when its plan named the
    rule in words, goes on once converted; a plan of this version is left as it is."""
    from fppo_jax.analysis.study_plan import LEGACY_WORDS

    plan = tmp_path / "study" / "plan.json"
    plan.parent.mkdir()
    recorded = {"tasks": ["cartpole"], "test": LEGACY_WORDS["test"] + " (fppo_jax.sequential)"}
    recorded |= {"level": 0.05, "margin": 0.2}
    recorded |= {"equivalence_test": LEGACY_WORDS["equivalence_test"] + " (fppo_jax.sequential)"}
    recorded |= {"commit": "a" * 40}
    plan.write_text(json.dumps(recorded, indent=2))
    other = tmp_path / "study" / "decisions.json"
    other.write_text('{"note": "x (fppo_jax.sequential)"}')
    done = run_script(EXPERIMENTS / "convert_plans.py", str(tmp_path), cwd=EXPERIMENTS)
    assert done.returncode == 0 and f"converted {plan}" in done.stdout
    converted = plan.read_text()
    assert list(json.loads(converted).items()) == [
        ("tasks", ["cartpole"]),
        ("rule", {"id": "sequential-mann-whitney-holm", "version": 1}),
        ("level", 0.05),
        ("margin", 0.2),
        ("commit", "a" * 40),
    ]
    assert other.read_text() == '{"note": "x (fppo_jax.sequential)"}'  # only plans
    again = run_script(EXPERIMENTS / "convert_plans.py", str(tmp_path), cwd=EXPERIMENTS)
    assert again.returncode == 0 and again.stdout == "" and plan.read_text() == converted


def _tuned_families(monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    monkeypatch.syspath_prepend(str(EXPERIMENTS / "studies"))
    return importlib.import_module("_tuned_families")


def test_the_tuned_write_up_decides_the_mujoco_family_the_plan_names_as_one(monkeypatch):
    # The plan's MuJoCo family is 15 comparisons; each task's study decided its 5 alone.
    families = _tuned_families(monkeypatch)
    plan = json.loads((EXPERIMENTS / "plans" / "tuned.json").read_text())
    tasks = families.planned_families(plan)["mujoco"]
    family = families.decide_family(EXPERIMENTS / "results", "mujoco", tasks)
    assert family.split and len(family.replayed) == 15
    # Each study replayed alone gives what it recorded: the replay is the rule the studies ran.
    assert all(families.same_as_recorded(one.alone, one.row) for one in family.replayed)
    lost = {
        (one.task, one.candidate): one.planned
        for one in family.replayed
        if families.standing(one) != "stands"
    }
    assert sorted(lost) == [("hopper", "fppo-lp"), ("hopper", "fppo-qp"), ("swimmer", "spo")]
    # Each is undecided at the seeds its study ran: the study stopped it there.
    assert [(d.decision, d.seeds) for d in lost.values()] == [(None, 20), (None, 40), (None, 30)]
    fppo_lp, fppo_qp, spo = lost.values()
    assert (round(fppo_lp.z, 2), round(fppo_lp.boundary, 2)) == (-4.46, 4.53)
    assert [round(bound, 2) for bound in fppo_qp.interval] == [0.31, 0.71]
    assert (round(spo.z, 2), round(spo.boundary, 2)) == (3.52, 3.64)
    kept = [one for one in family.replayed if (one.task, one.candidate) not in lost]
    assert len(kept) == 12
    assert all(
        (one.planned.decision, one.planned.seeds) == (one.alone.decision, one.alone.seeds)
        for one in kept
    )


def test_the_tuned_write_up_decides_the_classic_family_as_its_one_study_did(monkeypatch):
    families = _tuned_families(monkeypatch)
    tasks = ["cartpole", "acrobot", "mountaincar"]
    family = families.decide_family(EXPERIMENTS / "results", "classic", tasks)
    assert not family.split and len(family.replayed) == 15
    assert all(families.same_as_recorded(one.planned, one.row) for one in family.replayed)


def test_a_planned_family_with_a_task_not_recorded_is_not_decided(monkeypatch, tmp_path):
    # Hopper's and HalfCheetah's studies without Swimmer's: 10 of the family's 15 comparisons,
    # which would be decided at a larger share of the level than the plan's family gives them.
    families = _tuned_families(monkeypatch)
    recorded = EXPERIMENTS / "results" / "tuned" / "mujoco"
    (tmp_path / "tuned" / "mujoco").mkdir(parents=True)
    for task in ("hopper", "halfcheetah"):
        (tmp_path / "tuned" / "mujoco" / f"study-{task}").symlink_to(recorded / f"study-{task}")
    tasks = ["hopper", "halfcheetah", "swimmer"]
    with pytest.raises(families.FamilyNotAssembled, match="swimmer has no study with its decis"):
        families.decide_family(tmp_path, "mujoco", tasks)
    report = tmp_path / "tuned.md"
    script = EXPERIMENTS / "studies" / "tuned_verdict.py"
    done = run_script(script, "--results", str(tmp_path), "--output", str(report), cwd=EXPERIMENTS)
    assert done.returncode == 0, done.stdout + done.stderr
    assert (
        "Not decided here: the plan's MuJoCo family (hopper, halfcheetah and swimmer) cannot be "
        "decided as one: swimmer has no study"
    ) in report.read_text()


def test_a_replay_that_does_not_give_a_study_s_recorded_decisions_is_refused(monkeypatch, tmp_path):
    # Hopper's study with one recorded z moved in its last digits: the replay no longer matches.
    families = _tuned_families(monkeypatch)
    recorded = EXPERIMENTS / "results" / "tuned" / "mujoco" / "study-hopper"
    study = tmp_path / "tuned" / "mujoco" / "study-hopper"
    study.mkdir(parents=True)
    (study / "hopper").symlink_to(recorded / "hopper")
    (study / "plan.json").write_text((recorded / "plan.json").read_text())
    decisions = json.loads((recorded / "decisions.json").read_text())
    decisions["comparisons"][3]["z"] += 1e-6  # fppo-lp's
    (study / "decisions.json").write_text(json.dumps(decisions))
    with pytest.raises(SystemExit, match="does not give its recorded decision of hopper fppo-lp"):
        families.decide_family(tmp_path, "mujoco", ["hopper"])


def test_a_family_s_study_of_a_namespaced_task_is_read_from_the_library_s_folder(
    monkeypatch, tmp_path
):
    # Hopper's study as if its task were native/hopper, whose runs a study records under
    # native__hopper/: the replay reads them there, and gives the study's decisions.
    families = _tuned_families(monkeypatch)
    recorded = EXPERIMENTS / "results" / "tuned" / "mujoco" / "study-hopper"
    study = tmp_path / "tuned" / "mujoco" / "study-hopper"
    study.mkdir(parents=True)
    (study / "native__hopper").symlink_to(recorded / "hopper")
    for name in ("plan.json", "decisions.json"):
        text = (recorded / name).read_text()
        (study / name).write_text(text.replace('"hopper"', '"native/hopper"'))
    family = families.decide_family(tmp_path, "mujoco", ["native/hopper"])
    assert {one.task for one in family.replayed} == {"native/hopper"}
    assert all(families.same_as_recorded(one.alone, one.row) for one in family.replayed)


SCRIPTS = sorted(p for p in EXPERIMENTS.rglob("*.py") if "results" not in p.parts)


def _imported_names(path: Path) -> list[tuple[str, str | None]]:
    """Every ``fppo_jax`` import of `path`, anywhere in it: (module, name), name None for
    ``import fppo_jax.x``."""
    import ast

    found: list[tuple[str, str | None]] = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "fppo_jax":
            found += [(str(node.module), alias.name) for alias in node.names]
        elif isinstance(node, ast.Import):
            found += [(a.name, None) for a in node.names if a.name.split(".")[0] == "fppo_jax"]
    return found


def test_every_scripts_imports_of_the_library_resolve():
    """A script in experiments/ that imports a name the library no longer has fails here, on
    every import, those inside a function too, without running the script."""
    unresolved = []
    for path in SCRIPTS:
        for module, name in _imported_names(path):
            imported = importlib.import_module(module)
            if name is not None and not hasattr(imported, name):
                try:
                    importlib.import_module(f"{module}.{name}")
                except ModuleNotFoundError:
                    unresolved.append(f"{path.relative_to(EXPERIMENTS)}: {module}.{name}")
    assert len(SCRIPTS) > 30 and not unresolved, unresolved


def test_the_tune_benchmark_runs_tiny_into_a_temporary_directory(tmp_path):
    script = EXPERIMENTS / "benchmarks" / "bench_tune.py"
    helped = run_script(script, "--help", cwd=EXPERIMENTS)
    assert helped.returncode == 0 and "--trials" in helped.stdout
    flags = ["--tiny", "--trials", "2", "--eta", "2", "--steps", "1024", "--repeats", "1"]
    done = run_script(script, *flags, "--results", str(tmp_path), cwd=EXPERIMENTS)
    assert done.returncode == 0, done.stdout + done.stderr
    written = (tmp_path / "bench_tune_cartpole.md").read_text()
    assert "| fppo-jax tune (one program) |" in written and "Wall time" in written
    assert "then the race |" in written  # the usual way trains the tune's race too
    assert "A first tune, cold (nothing cached):" in written and "compiling at most" in written


def test_bench_trust_names_a_tune_going_on_by_its_rounds_runs_and_parts(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    monkeypatch.syspath_prepend(str(EXPERIMENTS / "benchmarks"))
    bench_trust = importlib.import_module("bench_trust")
    tune = tmp_path / "trust" / "hopper" / "tune"
    for rung, seeds in enumerate((2, 4)):
        trials = [{"trial": t, "seed_scores": [1.0] * seeds} for t in range(3 - rung)]
        (tune / "hopper" / f"rung-{rung}").mkdir(parents=True)
        scores = {"arms": {"ppo": {"trials": trials}}}
        (tune / "hopper" / f"rung-{rung}" / "scores.json").write_text(json.dumps(scores))
    plan = {"budget": {"hopper": {"full_runs_per_arm": 94.0}}, "search": {"seeds_per_round": 2}}
    (tune / "tune.json").write_text(json.dumps(plan))
    record = {"parts": "3", "wall_seconds": 5400.0, "commit": "210407d8b7", "machine": "B"}
    (tune / "run.json").write_text(json.dumps(record))
    # A record from before the machines were listed names its last part's machine alone.
    assert bench_trust.progress_lines(tmp_path) == [
        "- hopper: its tune goes on: 2 rounds, 10 of its 94 full runs, 3 parts of 90 minutes "
        "in all (the last at 210407d), on B."
    ]
    (tune / "run.json").write_text(json.dumps({**record, "machines": ["A", "B"]}))
    assert bench_trust.progress_lines(tmp_path)[0].endswith("(the last at 210407d), on A and B.")
    tunes = [{"task": "acrobot", "machines": ["A"]}, {"task": "hopper", "machines": ["A", "B"]}]
    tunes.append({"task": "cartpole", "machines": ["A"]})
    assert bench_trust.machine_lines(tunes) == ["- acrobot, cartpole: A", "- hopper: A and B"]
    # A round goes on in shares of its run-shape groups, each a part of its own.
    assert bench_trust.share("2/3") == (2, 3)
    with pytest.raises(argparse.ArgumentTypeError, match="a part is K/N, such as 1/3, got 'x'"):
        bench_trust.share("x")


def test_bench_trust_goes_on_with_the_test_sweep_a_stopped_call_left(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    monkeypatch.syspath_prepend(str(EXPERIMENTS / "benchmarks"))
    bench_trust = importlib.import_module("bench_trust")
    default = {"learning_rate": 3e-4, "num_steps": 256, "num_epochs": 10}
    chosen = {"learning_rate": 1e-4, "num_steps": 64, "num_epochs": 5}
    recorded = types.SimpleNamespace(
        chosen=lambda task, arm: chosen,
        results={"halfcheetah": {"ppo": {"default": {"setting": default}}}},
    )
    monkeypatch.setattr(bench_trust.fppo_jax, "load_tune", lambda where: recorded)
    task = tmp_path / "trust" / "halfcheetah"
    (task / "tune").mkdir(parents=True)
    (task / "tune" / "results.json").write_text("{}")
    # A run shape of its own: the chosen and the default are two sweeps, each its shape.
    sweeps = bench_trust.test_sweeps("halfcheetah", task / "tune", task / "test")
    assert [(where.name, grid, shape) for where, grid, shape in sweeps] == [
        ("test", [{"variant": "ppo", "learning_rate": 1e-4}], {"num_steps": 64, "num_epochs": 5}),
        (
            "test-default",
            [{"variant": "ppo", "learning_rate": 3e-4}],
            {"num_steps": 256, "num_epochs": 10},
        ),
    ]
    trained: list[str] = []
    monkeypatch.setattr(
        bench_trust,
        "test_sweep",
        lambda task, grid, rec, where, seeds, shape: trained.append(where.name),
    )
    (task / "test").mkdir()
    (task / "test" / "sweep.json").write_text("{}")  # the call stopped after the first sweep
    assert not bench_trust.test_recorded("halfcheetah", task)
    assert bench_trust.progress_lines(tmp_path) == [
        "- halfcheetah: its tune is recorded, its test goes on: 1 of its 2 sweeps recorded "
        "(test-default/ to train)."
    ]
    bench_trust.test_task("halfcheetah", task / "tune", task / "test", 20, {})
    assert trained == ["test-default"]  # the recorded sweep is not trained again
    (task / "test-default").mkdir()
    (task / "test-default" / "sweep.json").write_text("{}")
    assert bench_trust.test_recorded("halfcheetah", task)
    assert bench_trust.progress_lines(tmp_path) == []
    # The same shape: one sweep, the chosen beside the default; the default kept: itself alone.
    chosen = {**default, "learning_rate": 1e-4}
    [(where, grid, _)] = bench_trust.test_sweeps("halfcheetah", task / "tune", task / "test")
    assert where.name == "test" and [g["learning_rate"] for g in grid] == [1e-4, 3e-4]
    chosen = default
    [(_, grid, _)] = bench_trust.test_sweeps("halfcheetah", task / "tune", task / "test")
    assert grid == [{"variant": "ppo", "learning_rate": 3e-4}]


def test_bench_trust_reads_the_recorded_protocols_tuned_ppo_on_the_test_seeds(
    tmp_path, monkeypatch
):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    monkeypatch.syspath_prepend(str(EXPERIMENTS / "benchmarks"))
    bench_trust = importlib.import_module("bench_trust")
    results = EXPERIMENTS / "results"
    scores = bench_trust.recorded_protocol(results, "cartpole", [1, 3])
    assert scores is not None and len(scores) == 2
    # By seed, in the order asked for.
    assert np.array_equal(bench_trust.recorded_protocol(results, "cartpole", [3, 1]), scores[::-1])
    assert bench_trust.recorded_protocol(results, "cartpole", [1, 10**6]) is None  # not scored
    assert bench_trust.recorded_protocol(results, "walker2d", [1]) is None  # no recorded study
    assert bench_trust.recorded_protocol(tmp_path, "cartpole", [1]) is None  # not under these
    found = [{"task": "hopper", "p": (0.5,) * 3, "iqm": 2866.0, "kept": True}]
    found.append({**found[0], "task": "halfcheetah", "recorded_p": (0.28, 0.12, 0.46)})
    found.append({**found[0], "task": "cartpole", "recorded_p": (0.57, 0.5, 0.65)})
    found.append({**found[0], "task": "swimmer", "recorded_p": (0.78, 0.61, 0.92)})
    lines = bench_trust.goal_lines(found)
    assert (
        "- Beside it, the recorded protocol's tuned PPO (9 × 2, η = 3) below the same default "
        "(P's point below 0.5; its interval in the table): on halfcheetah."
    ) in lines
    # Where the race kept a default that the recorded setting beats, the search fell short.
    assert [line for line in lines if "a better setting" in line] == [
        "- On swimmer a better setting than the default exists: the recorded protocol's tuned "
        "PPO beats it, P = 0.78 [0.61, 0.92]; this tune's search found none."
    ]


def test_bench_trust_says_what_stands_in_the_way_of_a_missed_goal(monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    monkeypatch.syspath_prepend(str(EXPERIMENTS / "benchmarks"))
    bench_trust = importlib.import_module("bench_trust")
    found = [
        {"task": "hopper", "p": (0.5, 0.5, 0.5), "iqm": 2866.0, "kept": True},
        {"task": "swimmer", "p": (0.6, 0.45, 0.75), "iqm": 100.0, "kept": False},
    ]
    lines = bench_trust.goal_lines(found)
    assert "- On the MuJoCo tasks the interval above 0.5: **missed** on hopper, swimmer." in lines
    # Only where the race kept the default is P ½ by construction; swimmer's is a wide interval.
    way = [line for line in lines if line.startswith("- What stands in the way")]
    assert way == [
        "- What stands in the way on hopper: the race kept the default (no finalist was shown "
        "better on the validation seeds), so tuned and default are the same runs and P is ½ by "
        "construction."
    ]
    assert "- hopper: IQM 2866 against 2,410: met." in lines
    assert "- swimmer: IQM 100 against 282: **missed**." in lines
    assert bench_trust.goal_lines(found[1:])[-2:] == [
        "- On the MuJoCo tasks the interval above 0.5: **missed** on swimmer.",
        "- swimmer: IQM 100 against 282: **missed**.",
    ]


def test_tuned_v2_writes_each_recorded_rung_its_runs_race_and_what_remains(tmp_path):
    # The trust benchmark's CartPole tune stands in for the classic family's: one arm, three
    # rounds of 9 trials × 2 seeds, then 3 finalists and the default on 10 validation seeds.
    shutil.copytree(EXPERIMENTS / "results/trust/cartpole/tune", tmp_path / "tuned-v2/classic/tune")
    # Its rungs predate machines in records: two are made to name theirs, one its shares'
    # (one share's recorded before shares named theirs).
    machines_of = ((1, ["X, 2 cores"]), (2, ["Y, 16 cores", "not recorded", "X, 2 cores"]))
    for rung, machines in machines_of:
        path = tmp_path / f"tuned-v2/classic/tune/cartpole/rung-{rung}/scores.json"
        path.write_text(json.dumps({**json.loads(path.read_text()), "machines": machines}))
    output = tmp_path / "tuned-v2.md"
    done = run_script(
        EXPERIMENTS / "studies/tuned_v2.py",
        *("--results", str(tmp_path), "--output", str(output)),
        cwd=EXPERIMENTS,
    )
    assert done.returncode == 0, done.stderr
    rows = [
        line.split(" | ")[:4] for line in output.read_text().splitlines() if "| classic |" in line
    ]
    assert rows == [
        *(["| classic", "cartpole", f"round {k}", "18"] for k in (1, 2, 3)),
        ["| classic", "cartpole", "validation race", "40"],
    ]
    assert "| ppo: default kept |" in output.read_text()
    machines = [
        line.rsplit(" | ", 1)[1]
        for line in output.read_text().splitlines()
        if "| classic |" in line
    ]
    assert machines == ["— |", "m1 |", "m2, —, m1 |", "— |"]
    assert "- m1: X, 2 cores\n- m2: Y, 16 cores\n" in output.read_text()
    assert "- classic: the study not started." in done.stdout
    assert "- mujoco: the tune not started." in done.stdout


def test_tuned_v2_writes_a_decided_study_with_tuned_ppo_against_its_concurrent_default(tmp_path):
    # The second verdict's classic tune, where every race kept its default, with the first
    # verdict's classic study standing in for its study (the same three tasks, finished). On
    # CartPole the tune's record is made to say PPO's race chose trial 5, and PPO's default
    # "trained beside it" on the first group of seeds is that group itself: tuned and default
    # are the same runs, seed for seed. Elsewhere the default was kept: nothing trains beside.
    family = tmp_path / "tuned-v2/classic"
    shutil.copytree(EXPERIMENTS / "results/tuned-v2/classic/tune", family / "tune")
    shutil.copytree(EXPERIMENTS / "results/tuned/classic/study", family / "study")
    chosen = json.loads((family / "tune/results.json").read_text())
    chosen["cartpole"]["ppo"]["chosen"]["trial"] = 5
    (family / "tune/results.json").write_text(json.dumps(chosen))
    output = tmp_path / "tuned-v2.md"

    def written() -> str:
        done = run_script(
            EXPERIMENTS / "studies/tuned_v2.py",
            *("--results", str(tmp_path), "--output", str(output)),
            cwd=EXPERIMENTS,
        )
        assert done.returncode == 0, done.stderr
        return done.stdout

    assert "- classic: PPO's default beside the study goes on." in written()
    assert "| cartpole | 5 | — | — | not trained yet | — |" in output.read_text()
    group = family / "study/cartpole/group-1"
    shutil.copytree(group, family / "study/ppo-default/cartpole/group-1")
    assert "beside the study goes on" not in written()
    text = output.read_text()
    decided = json.loads((family / "study/decisions.json").read_text())["comparisons"]
    candidates = {c["candidate"] for c in decided}
    rows = [line.split(" | ")[:4] for line in text.splitlines() if line.startswith("| ")]
    assert [row for row in rows if row[1] in candidates] == [
        [f"| {c['task']}", c["candidate"], c["decision"] or "undecided", str(c["seeds"])]
        for c in decided
    ]
    same = "200.0 [200.0, 200.0]"
    assert f"| cartpole | 5 | 10 | {same} | {same} | 0.50 [0.50, 0.50] |" in text
    assert "| acrobot | 0, the default | 50 |" in text
    assert "| acrobot | 0, the default | 50 | -82.1 [-83.6, -80.5] | the same runs | — |" in text
    assert "| classic | ppo-default/cartpole/group-1 | 60 |" in text
