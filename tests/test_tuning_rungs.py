"""fppo_jax.analysis.tuning_rungs: a rung split into shares joins into the rung trained whole,
bit for bit; a missing share is refused by name, a recorded one not trained again and another
split of a rung refused, naming the one recorded; a trial
that diverges scores below every other and stops."""

import json

import numpy as np
import pytest
from helpers import TUNE_ARMS as ARMS
from helpers import TUNE_SMALL as SMALL
from helpers import rung_scores

from fppo_jax.analysis import population
from fppo_jax.analysis.preregistration import commit
from fppo_jax.analysis.tuning import tune
from fppo_jax.analysis.tuning_draws import import_optuna
from fppo_jax.errors import InvalidInput
from fppo_jax.store.machine import describe_machine

# Runs per compiled call of the split tunes: 3 trials × 2 seeds. Rung 0's 16 runs train in
# groups of 6, 6 and 4 (filled up to 6), rung 1's 8 in groups of 6 and 2, rung 2's 4 in one,
# the validation race's 16 as rung 0's.
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
    """Each arm's trials in the tune's Optuna studies (named after the tune, as its plan
    records)."""
    prefix = json.loads((directory / "tune.json").read_text())["storage"]["studies"]
    storage = f"sqlite:///{directory}/optuna.db"
    return {
        arm: [
            (t.number, t.state, t.value, t.intermediate_values, t.params)
            for t in import_optuna()
            .load_study(study_name=f"{prefix}/cartpole/{arm}", storage=storage)
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
    # The validation race's 2 arms × 2 entrants × 4 seeds make 3 groups, one a part.
    shares = [sorted(p.name for p in rung.glob("part-*")) for rung in _rungs(tmp_path / "split")]
    three = ["part-1", "part-2", "part-3"]
    assert shares == [three, ["part-1", "part-2"], ["part-1"], three]
    said = capsys.readouterr().err
    assert "cartpole: rung 2 of 4, part 3 of 3: nothing to train, the rung's 8 runs make 2" in said
    # Each rung and each share names the code that recorded it, for parts run at other commits.
    recorded = [json.loads(p.read_text()) for p in (tmp_path / "split").rglob("scores.json")]
    assert len(recorded) == 4 + 3 + 2 + 1 + 3
    assert {found["commit"] for found in recorded} == {commit()}
    # And the machine its seconds are of: a share its own, a rung each of its shares' once.
    shares = [found for found in recorded if "part" in found]
    assert {found["machine"] for found in shares} == {describe_machine()}
    rungs = [found for found in recorded if "part" not in found]
    assert all(found["machines"] == [describe_machine()] for found in rungs)


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
        patch.setattr(population, "compile_program", compiled)
        assert not tune("cartpole", ARMS, output=tmp_path, part=(1, 2), **arguments).finished
        # Another split of the same rung is refused, naming the one recorded, whichever part.
        for part in ((1, 3), (3, 3)):
            with pytest.raises(
                InvalidInput,
                match=r"^cartpole: rung 1 is split into 2 parts, not 3 \(part 1 of 2 is recorded "
                r"in .*rung-0/part-1\): train its others with --part K/2 \(part=\(K, 2\)\), or "
                r"remove .*rung-0/part-\* to split it into 3$",
            ):
                tune("cartpole", ARMS, output=tmp_path, part=part, **arguments)
    assert share.read_text() == recorded
    assert sorted(p.name for p in share.parent.parent.iterdir()) == ["part-1"]
    with pytest.raises(
        InvalidInput,
        match=r"cartpole: rung 1 is split into 2 parts and part 2 is missing .* --part 2/2",
    ):
        tune("cartpole", ARMS, output=tmp_path, **arguments)
    assert not (tmp_path / "cartpole/rung-0/scores.json").exists()
    # The join is the tune of its plan: another chunk is refused, naming it.
    with pytest.raises(InvalidInput, match="chunk = 6, not 4"):
        tune("cartpole", ARMS, output=tmp_path, **{**arguments, "chunk": 4})
    # Shares trained on other machines, or recorded before shares named theirs: the rung
    # names each machine once, in the parts' order.
    tune("cartpole", ARMS, output=tmp_path, part=(2, 2), **arguments)
    first, second = (tmp_path / f"cartpole/rung-0/part-{k}/scores.json" for k in (1, 2))
    first.write_text(json.dumps({**json.loads(first.read_text()), "machine": "another"}))
    older = json.loads(second.read_text())
    second.write_text(json.dumps({k: v for k, v in older.items() if k != "machine"}))
    tune("cartpole", ARMS, output=tmp_path, rungs=0, **arguments)
    joined = json.loads((tmp_path / "cartpole/rung-0/scores.json").read_text())
    assert joined["machines"] == ["another", "not recorded"]


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
    trials = optuna_trials(tmp_path)["ppo"]
    assert [number for number, state, *_ in trials if state.name == "FAIL"] == diverged
    assert "| ppo | " in (tmp_path / "report.md").read_text()
