"""fppo_jax.store.saved_policy: a trained policy saved on its own (policy.json and policy.npz),
loaded back bit for bit, never overwritten unasked, and damage reported by directory."""

import json
import re
from pathlib import Path

import jax
import numpy as np
import pytest
from conftest import IN_CHUNKS
from helpers import assert_bitwise_equal
from test_policy import gaussian_policy

from fppo_jax import IncompatibleFormat, load_policy, train
from fppo_jax.cli import main
from fppo_jax.core.policy import Policy
from fppo_jax.store.files import tree_digest
from fppo_jax.store.numpy_policy import NumpyPolicy
from fppo_jax.store.saved_policy import FORMAT, check_no_saved_policy, read_policy, save_policy

TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
RUN = {"env": "cartpole", "variant": "fppo-qp", "seed": 3, "total_steps": 128 * 20, **TINY}


def test_a_saved_policy_acts_as_the_trained_policy_and_is_not_overwritten(tmp_path, capsys):
    result = train(**RUN, **IN_CHUNKS)  # in one-update chunks: test_checkpoint's program
    assert result.save(tmp_path / "policy") == tmp_path / "policy"
    policy, record = read_policy(tmp_path / "policy")
    assert_bitwise_equal(policy.arrays(), result.policy.arrays())
    obs = np.random.default_rng(0).normal(size=(64, 4)).astype(np.float32)
    np.testing.assert_array_equal(policy(obs), result.policy(obs))
    key = jax.random.key(1)
    np.testing.assert_array_equal(policy(obs, key), result.policy(obs, key))
    assert record["config"] == json.loads(json.dumps(result.config))
    assert (record["kind"], record["update"]) == ("policy", 20)

    with pytest.raises(ValueError, match="already holds a saved policy; pass overwrite=True"):
        result.save(tmp_path / "policy")
    result.save(tmp_path / "policy", overwrite=True)
    assert sorted(p.name for p in (tmp_path / "policy").iterdir()) == ["policy.json", "policy.npz"]

    assert main(["eval", "--policy", str(tmp_path / "policy"), "--episodes", "2"]) == 0
    assert "fppo-qp on cartpole, seed 3: saved policy at update 20" in capsys.readouterr().out
    assert main(["eval", "--policy", str(tmp_path / "policy"), "--render", "a.mp4"]) == 2
    assert (
        "cartpole is a classic (gymnax) task, which MuJoCo cannot render" in capsys.readouterr().err
    )
    assert main(["eval", "--policy", str(tmp_path / "policy"), "--render", "a.avi"]) == 2
    assert (
        "render to a .png (image strip), a .gif (animation) or an .mp4" in capsys.readouterr().err
    )


def test_cli_saves_the_trained_policy_and_refuses_before_training_to_overwrite_it(tmp_path, capsys):
    flags = ["train", "--steps", "256", "--save-policy", str(tmp_path), "--quiet"]
    flags += ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
    assert main(flags) == 0
    assert f"wrote {tmp_path}/policy.json, policy.npz" in capsys.readouterr().out
    assert load_policy(tmp_path).action_space.n == 2
    saved = (tmp_path / "policy.json").read_bytes()
    assert main(flags) == 2
    out, err = capsys.readouterr()
    assert "already holds a saved policy; remove its policy.json and policy.npz to" in err
    assert "overwrite=True" not in err and "updates" not in out  # no such flag; nothing trained
    with pytest.raises(FileNotFoundError, match=r"policy\.json is a file: name the directory"):
        load_policy(tmp_path / "policy.json")
    assert (tmp_path / "policy.json").read_bytes() == saved


def save_gaussian_policy(directory: Path) -> Policy:
    policy = gaussian_policy()
    save_policy(directory, policy, {"config": {"env": "mine"}, "update": 7})
    return policy


def test_a_saved_gaussian_policy_round_trips_bit_for_bit(tmp_path):
    policy = save_gaussian_policy(tmp_path)
    again = load_policy(tmp_path)
    assert_bitwise_equal(again.arrays(), policy.arrays())
    assert (again.action_space, again.hidden_sizes) == (policy.action_space, (8,))
    obs = np.random.default_rng(0).normal(size=(16, 3)).astype(np.float32) * 5
    np.testing.assert_array_equal(again(obs), policy(obs))
    key = jax.random.key(2)
    np.testing.assert_array_equal(again(obs, key), policy(obs, key))


@pytest.mark.parametrize(
    "edit, found",
    [
        (lambda d: d["action_space"].update(low=[-1.0] * 3, high=[1.0] * 3), "network for its"),
        (lambda d: d.update(hidden_sizes=[16]), "['Dense_0']['bias'] is (8,), expected (16,)"),
    ],
)
def test_a_policy_json_edited_apart_from_its_arrays_is_refused_at_load(tmp_path, edit, found):
    save_gaussian_policy(tmp_path)
    path = tmp_path / "policy.json"
    saved = json.loads(path.read_text())
    edit(saved["policy"])
    path.write_text(json.dumps(saved))
    with pytest.raises(
        ValueError, match=rf"saved policy in {tmp_path} is damaged .*{re.escape(found)}"
    ):
        load_policy(tmp_path)


@pytest.mark.parametrize("how", ["truncated", "replaced"])
def test_a_damaged_saved_policy_is_reported_naming_its_directory(tmp_path, how):
    policy = save_gaussian_policy(tmp_path)
    arrays = tmp_path / "policy.npz"
    if how == "truncated":
        arrays.write_bytes(arrays.read_bytes()[:-100])
    else:  # a well-formed file with other values: only the digest tells
        flat = dict(np.load(arrays))
        flat["obs_stats/mean"] = np.asarray(policy.obs_stats.mean) + 1
        with open(arrays, "wb") as f:
            np.savez(f, **flat)
    with pytest.raises(ValueError, match=f"saved policy in {tmp_path} is damaged"):
        load_policy(tmp_path)


def test_a_policy_json_that_is_not_an_object_is_damage(tmp_path):
    save_gaussian_policy(tmp_path)
    (tmp_path / "policy.json").write_text("[1]")
    damaged = r"is damaged \(DamagedArtifact: .*policy.json holds a list, not an object"
    with pytest.raises(ValueError, match=damaged):
        load_policy(tmp_path)


def test_a_directory_with_neither_a_policy_nor_checkpoints_is_refused_by_name(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("not a policy")
    message = f"{tmp_path} holds neither a saved policy (policy.json and policy.npz) nor checkp"
    with pytest.raises(FileNotFoundError, match=re.escape(message)):
        load_policy(tmp_path)
    assert main(["eval", "--checkpoint", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err


def test_the_saved_files_hold_the_record_the_description_and_the_arrays_by_path(tmp_path):
    policy = gaussian_policy()
    record = {"config": {"env": "mine", "sizes": (8,), "k": np.float32(0.5)}, "update": np.int64(7)}
    assert save_policy(tmp_path / "new" / "dir", policy, record) == tmp_path / "new" / "dir"
    where = tmp_path / "new" / "dir"
    assert sorted(p.name for p in where.iterdir()) == ["policy.json", "policy.npz"]
    saved = json.loads((where / "policy.json").read_text())
    assert saved["config"] == {"env": "mine", "sizes": [8], "k": 0.5}  # as JSON has them
    assert (saved["update"], saved["kind"]) == (7, "policy")
    assert saved["policy"] == policy.describe()
    with np.load(where / "policy.npz") as npz:
        arrays = dict(npz)
    assert set(arrays) == {
        "params/params/MLP_0/Dense_0/kernel",
        "params/params/MLP_0/Dense_0/bias",
        "params/params/MLP_0/Dense_1/kernel",
        "params/params/MLP_0/Dense_1/bias",
        "params/params/log_std",
        "obs_stats/mean",
        "obs_stats/var",
        "obs_stats/count",
    }
    np.testing.assert_array_equal(arrays["obs_stats/var"], policy.obs_stats.var)
    assert saved["digest"] == tree_digest(arrays)
    loaded, again = read_policy(where)
    assert again == saved
    assert_bitwise_equal(loaded.arrays(), policy.arrays())


def test_a_saved_policy_is_replaced_only_when_asked(tmp_path):
    check_no_saved_policy(tmp_path / "missing")  # nothing there: nothing to refuse
    check_no_saved_policy(tmp_path)
    save_gaussian_policy(tmp_path)
    message = f"{tmp_path} already holds a saved policy; use --force to replace it, or choose "
    with pytest.raises(ValueError, match=re.escape(message)):
        check_no_saved_policy(tmp_path, replace="use --force")
    check_no_saved_policy(tmp_path, overwrite=True)
    written = (tmp_path / "policy.json").read_bytes()
    with pytest.raises(ValueError, match="already holds a saved policy; pass overwrite=True to"):
        save_policy(tmp_path, gaussian_policy(), {"config": {}, "update": 8})
    assert (tmp_path / "policy.json").read_bytes() == written
    save_policy(tmp_path, gaussian_policy(), {"config": {}, "update": 8}, overwrite=True)
    assert read_policy(tmp_path)[1]["update"] == 8


def test_a_missing_directory_or_arrays_file_is_reported(tmp_path):
    with pytest.raises(FileNotFoundError, match=f"policy or checkpoint directory {tmp_path / 'x'}"):
        load_policy(tmp_path / "x")
    save_gaussian_policy(tmp_path)
    (tmp_path / "policy.npz").unlink()
    with pytest.raises(
        ValueError, match=rf"saved policy in {tmp_path} is damaged \(FileNotFoundError: "
    ):
        load_policy(tmp_path)


def test_a_saved_policy_of_another_format_is_refused_and_one_without_a_format_is_the_first(
    tmp_path,
):
    policy = save_gaussian_policy(tmp_path)
    path = tmp_path / "policy.json"
    saved = json.loads(path.read_text())
    assert saved.pop("format") == FORMAT == 1
    path.write_text(json.dumps(saved))  # as fppo-jax wrote it before formats were recorded
    assert_bitwise_equal(load_policy(tmp_path).arrays(), policy.arrays())
    assert NumpyPolicy.load(tmp_path).observation_size == policy.observation_size

    path.write_text(json.dumps({**saved, "format": 2}))  # as a newer fppo-jax would write it
    message = f"the saved policy in {tmp_path} was written by a newer version of fppo-jax"
    with pytest.raises(IncompatibleFormat, match=re.escape(message) + r" \(format 2; this one"):
        load_policy(tmp_path)
    assert json.loads(path.read_text())["format"] == 2  # left as it is
    with pytest.raises(ValueError, match="is in format 2; this file reads format 1"):
        NumpyPolicy.load(tmp_path)
