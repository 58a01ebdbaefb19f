"""fppo_jax.store.record: a run's typed record, its JSON (the layout every recorded run has) and
the one comparison of two records, naming what differs."""

import dataclasses
import json
from pathlib import Path

import pytest

from fppo_jax.core.config import TrainConfig
from fppo_jax.core.resolution import HYPERPARAMETER_DEFAULTS
from fppo_jax.run.prepare import prepare
from fppo_jax.store.files import IncompatibleFormat
from fppo_jax.store.record import RunRecord

RESULTS = Path(__file__).parent.parent / "experiments" / "results"
SHAPE = TrainConfig(total_steps=1024, num_envs=4, num_steps=32, num_minibatches=4, num_epochs=2)
OWN = {"mine": {"name": "mine", "hyperparameters": {"c": 1.0}, "digest": "ab", "import": None}}
TRAIN = RunRecord(
    "cartpole",
    "gymnax",
    "paper",
    SHAPE,
    setting={"variant": "mine", "epsilon": 0.2, "c": 1.0},
    seed=3,
    surrogates=OWN,
)
SWEEP = RunRecord(
    "cartpole",
    "gymnax",
    "paper",
    SHAPE,
    grid={"variant": ["ppo", "fppo-lp"], "alpha": [0.5, 1.0]},
    seeds=(0, 1, 2),
    part=(1, 2),
    runs_per_call=4,
)


def test_a_record_reads_back_as_it_was_written_in_the_layout_records_have():
    for record in (TRAIN, SWEEP, TRAIN.protocol()):
        assert RunRecord.from_json(json.loads(json.dumps(record.to_json()))) == record
    # A field added later is left out at the value every earlier run had.
    shape = [f.name for f in dataclasses.fields(TrainConfig) if f.name != "initial_log_std"]
    assert list(TRAIN.to_json()) == [
        *["variant", "epsilon", "c", "env", "backend", "seed", "surrogates", "preset"],
        *shape,
    ]
    assert list(SWEEP.to_json()) == [
        *["env", "backend", "grid", "seeds", "part", "preset"],
        *[*shape, "runs_per_call"],
    ]
    assert TRAIN.to_json()["hidden_sizes"] == [64, 64] and SWEEP.to_json()["part"] == [1, 2]


def test_every_recorded_run_reads_back_and_writes_its_record_unchanged():
    found = [
        (path, json.loads(path.read_text())["config"])
        for name in ("sweep.json", "policy.json")
        for path in RESULTS.rglob(name)
    ]
    machine = ("versions", "platform", "devices")  # what config.json adds beside the record
    found += [
        (path, {k: v for k, v in json.loads(path.read_text()).items() if k not in machine})
        for path in RESULTS.rglob("config.json")
    ]
    assert found
    for path, value in found:
        written = RunRecord.from_json(value, str(path)).to_json()
        assert list(written.items()) == list(value.items()), path


def test_a_record_of_another_format_is_refused_not_misread():
    with pytest.raises(IncompatibleFormat, match=r"a newer version of fppo-jax \(format 2;"):
        RunRecord.from_json({**SWEEP.to_json(), "format": 2}, "the sweep's record")
    lacking = {k: v for k, v in SWEEP.to_json().items() if k not in ("preset", "num_envs")}
    with pytest.raises(IncompatibleFormat, match="the sweep's record lacks preset, num_envs"):
        RunRecord.from_json(lacking, "the sweep's record")
    with pytest.raises(IncompatibleFormat, match="is not a run's record"):
        RunRecord.from_json([1, 2], "the sweep's record")
    with pytest.raises(IncompatibleFormat, match=r"its seeds \(5\) are not a list"):
        RunRecord.from_json({**SWEEP.to_json(), "seeds": 5}, "the sweep's record")


def test_differences_name_each_field_with_both_values():
    assert TRAIN.differences(TRAIN) == []
    changed = {
        "env": {"env": "acrobot"},
        "backend": {"backend": None},
        "preset": {"preset": "massive"},
        "seed": {"seed": 4},
        "variant": {"setting": {**TRAIN.setting, "variant": "ppo"}},
        "surrogates.mine": {"surrogates": {"mine": {**OWN["mine"], "digest": "cd"}}},
        "runs_per_call": {"runs_per_call": 8},
    }
    for name, change in changed.items():
        (differing,) = TRAIN.differences(dataclasses.replace(TRAIN, **change))
        assert differing.startswith(f"{name}: "), differing
    for field in dataclasses.fields(TrainConfig):
        value = getattr(SHAPE, field.name)
        other = {
            "total_steps": 2048,
            "num_envs": 8,
            "num_steps": 64,
            "num_minibatches": 2,
            "num_epochs": 3,
            "hidden_sizes": (32,),
            "resets_per_rollout": 2,
            "initial_log_std": -1.0,
        }.get(field.name, not value)
        shape = dataclasses.replace(SHAPE, **{field.name: other})
        (differing,) = TRAIN.differences(dataclasses.replace(TRAIN, config=shape))
        assert differing.startswith(f"{field.name}: "), differing
    assert TRAIN.differences(dataclasses.replace(TRAIN, seed=4), "in the checkpoint", "now") == [
        "seed: 3 in the checkpoint, 4 now"
    ]
    assert SWEEP.differences(
        dataclasses.replace(SWEEP, grid={"variant": ["ppo"], "alpha": [0.5, 1.0]}, seeds=(0,))
    ) == [
        'grid.variant: ["ppo", "fppo-lp"] here, ["ppo"] there',
        "seeds: [0, 1, 2] here, [0] there",
    ]
    assert SWEEP.differences(dataclasses.replace(SWEEP, part=None)) == [
        "part: [1, 2] here, none there"
    ]


def test_the_same_settings_make_equal_records():
    def record(**settings):
        names = tuple(HYPERPARAMETER_DEFAULTS)
        run = prepare("cartpole", settings, names, total_steps=None, preset="paper", backend="auto")
        return run.record()

    assert record(num_envs=4, learning_rate=1e-3) == record(num_envs=4)  # a setting is no protocol
    assert record(num_envs=4) != record(num_envs=8)
    assert record(num_envs=4).differences(record(num_envs=8)) == ["num_envs: 4 here, 8 there"]
    assert record(hidden_sizes=[32, 32]) == RunRecord.from_json(
        record(hidden_sizes=(32, 32)).to_json()
    )
