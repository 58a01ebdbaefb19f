"""Surrogates of one's own: declared once, checked before compiling, trained in the same
compiled program as the built-ins, and recorded so that two functions under one name are told
apart."""

import inspect
import json
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import IN_CHUNKS
from own_surrogates import clipped, my_clip_higher, my_ppo

import fppo_jax
from fppo_jax import objective, surrogate, sweep, train
from fppo_jax.cli import main
from fppo_jax.core.config import TrainConfig
from fppo_jax.core.surrogates import Range, check_in_range
from fppo_jax.store.record import RunRecord

TINY_STEPS = 512


def test_a_range_reads_as_its_message_shows_it():
    assert 0.5 in Range("(0, 1)") and 1.0 not in Range("(0, 1)") and 1.0 in Range("(0, 1]")
    assert 1.0 in Range(">= 1") and 0.99 not in Range(">= 1") and 0.0 not in Range("> 0")
    assert float("nan") not in Range("> 0") and -5.0 in Range("< 1")
    assert str(Range("(0, 1)")) == "in (0, 1)" and str(Range("> 0")) == "> 0"
    with pytest.raises(ValueError, match="a range must read like"):
        Range("positive")


@pytest.mark.parametrize(
    "value, valid, of, message",
    [
        (float("inf"), Range("> 0"), "", "x must be finite, got inf"),
        (float("inf"), None, "mine", "x must be finite for mine, got inf"),
        (0.0, Range("(0, 1]"), "", "x must be in (0, 1], got 0.0"),
        (0.5, Range(">= 1", "why"), "mine", "x must be >= 1 for mine, got 0.5 (why)"),
        (float("nan"), Range(">= 0"), "", "x must be >= 0, got nan"),
        (float("nan"), None, "mine", "x must be a number for mine, got nan"),
        (1e300, None, "", "x must be finite, got 1e+300, which training's float32 holds as inf"),
        (1e-300, Range("> 0"), "", "x must be > 0, got 1e-300, which training's float32 holds"),
        ("1", Range("> 0"), "", "x must be a number, got '1'"),
    ],
)
def test_every_hyperparameter_is_checked_by_one_function_with_one_message(
    value, valid, of, message
):
    with pytest.raises(ValueError, match=re.escape(message)):
        check_in_range("x", value, valid, of)
    assert check_in_range("x", np.float32(0.5), Range("(0, 1)")) == 0.5


def test_a_surrogate_is_accepted_where_a_variants_name_is():
    o = objective(my_clip_higher, eps_high=0.3)
    assert o.name == "my-clip-higher" and float(o.values["eps_high"]) == pytest.approx(0.3)
    hp = fppo_jax.hyperparameters(my_clip_higher, eps_low=0.1, learning_rate=1e-3)
    assert float(hp.objective.values["eps_low"]) == pytest.approx(0.1)
    # Its declared clip range bounds the R± diagnostics.
    below, above = o.clip_range()
    assert float(below) == pytest.approx(0.2) and float(above) == pytest.approx(0.3)
    assert fppo_jax.core.resolution.resolve("own_surrogates:my_ppo") is my_ppo


def test_a_user_surrogate_computes_what_its_function_does():
    r = jnp.linspace(0.5, 1.5, 21)
    a = jnp.where(jnp.arange(21) % 2 == 0, 1.5, -0.7)
    ours = jax.vmap(jax.value_and_grad(lambda r_, a_: objective(my_ppo)(r_, a_)))(r, a)
    builtin = jax.vmap(jax.value_and_grad(lambda r_, a_: objective("ppo")(r_, a_)))(r, a)
    np.testing.assert_array_equal(ours[0], builtin[0])
    np.testing.assert_array_equal(ours[1], builtin[1])


def _returns_a_scalar(ratio, advantage):
    return jnp.mean(ratio * advantage)


def _returns_integers(ratio, advantage):
    return (ratio * advantage).astype(jnp.int32)


def _not_finite_below_one(ratio, advantage):
    return jnp.log(ratio - 1.0) * advantage


def _branches_in_python(ratio, advantage):
    return ratio * advantage if ratio.mean() > 1 else -ratio * advantage


def _uses_numpy(ratio, advantage):
    return np.minimum(ratio, 1.2) * advantage


def _takes_a_float(ratio, advantage):
    return ratio * advantage * float(ratio.max())


def _has_no_slope(ratio, advantage):
    return jax.pure_callback(lambda r: r, ratio, ratio) * advantage  # a callback has no gradient


def _takes_an_unknown_input(ratio, advantage, beta_typo):
    return ratio * advantage


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        (("mine", 3.0), {}, "its function must be callable"),
        (("ppo", clipped), {}, "cannot be named 'ppo': that is a built-in"),
        (("Mine!", clipped), {}, "a surrogate's name must be lower-case"),
        (("mine", _takes_an_unknown_input), {}, "takes beta_typo, which it would not be given"),
        (("mine", lambda advantage: advantage), {}, "does not take ratio"),
        (("mine", clipped), {"beta": 1.0}, "does not take beta"),
        (("mine", clipped), {"ratio": 1.0}, "ratio is an input every surrogate gets"),
        (
            ("mine", my_clip_higher.function),
            {"eps_low": 0.2, "eps_high": -0.1, "ranges": {"eps_high": "> 0"}},
            "eps_high must be > 0 for mine, got -0.1",
        ),
        (
            ("mine", my_clip_higher.function),
            {"eps_low": 0.2, "eps_high": 0.3, "ranges": {"eps_hihg": "> 0"}},
            "surrogate 'mine' has no hyperparameter 'eps_hihg'",
        ),
        (
            ("mine", my_clip_higher.function),
            {"eps_low": 0.2, "eps_high": 0.3, "ranges": {"eps_high": 5}},
            r"ranges must map hyperparameters to a range's text, such as \{'eps_high': '> 0'\}",
        ),
        (
            ("mine", my_clip_higher.function),
            {"eps_low": 0.2, "eps_high": 0.3, "ranges": ["eps_high"]},
            r"ranges must map .*, got \['eps_high'\]",
        ),
        (
            ("mine", my_clip_higher.function),
            {"eps_low": 0.2, "eps_high": 0.3, "clip_range": ("eps_low", "high")},
            "surrogate 'mine' has no hyperparameter 'high'",
        ),
        (("mine", _returns_a_scalar), {}, "must return one value per sample"),
        (("mine", _returns_integers), {}, "must return floats, got int32"),
        (("mine", _not_finite_below_one), {}, "has a value that is not finite"),
        (
            ("mine", _branches_in_python),
            {},
            r"^surrogate 'mine' uses Python control flow \(if, while, and, or\) on traced values; "
            "use jnp.where$",
        ),
        (("mine", _uses_numpy), {}, r"^surrogate 'mine' turns a traced value into a NumPy array"),
        (
            ("mine", _takes_a_float),
            {},
            r"^surrogate 'mine' needs a traced value as a Python number",
        ),
        (("mine", _has_no_slope), {}, r"^surrogate 'mine' failed when tried: \w+: [^\n]*\Z"),
    ],
)
def test_a_bad_surrogate_gets_one_clear_error(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        surrogate(*args, **kwargs)


def test_a_user_surrogates_hyperparameters_are_checked_before_compiling():
    with pytest.raises(ValueError, match=r"eps_high must be > 0 for my-clip-higher, got -1\.0"):
        train("cartpole", my_clip_higher, eps_high=-1.0)
    with pytest.raises(ValueError, match=r"my-ppo has no hyperparameter alpha"):
        train("cartpole", my_ppo, alpha=1.3)
    with pytest.raises(ValueError, match="two different surrogates are named 'my-ppo'"):
        sweep("cartpole", {"variant": [my_ppo, surrogate("my-ppo", clipped)]})


def test_a_user_ppo_trains_bit_for_bit_like_the_builtin(tiny):
    # In one-update chunks, as the other tests here train: their compiled programs are reused.
    run = {"total_steps": TINY_STEPS, **IN_CHUNKS, **tiny}
    builtin = train("cartpole", "ppo", seed=2, **run)
    ours = train("cartpole", my_ppo, seed=2, **run)
    for name, values in builtin.metrics.items():
        np.testing.assert_array_equal(ours.metrics[name], values, err_msg=name)
    assert ours.config["variant"] == "my-ppo"
    assert ours.config["surrogates"]["my-ppo"]["import"] == "own_surrogates:my_ppo"
    builtin, ours = (
        sweep("cartpole", {"variant": [v]}, seeds=[2, 3], **run) for v in ("ppo", my_ppo)
    )
    for name, values in builtin.metrics.items():
        np.testing.assert_array_equal(ours.metrics[name], values, err_msg=name)


def test_a_sweep_mixing_builtins_and_own_surrogates_is_one_program(tiny, monkeypatch):
    compiled = []
    jit = jax.jit
    monkeypatch.setattr(
        fppo_jax.run.execution.jax, "jit", lambda f, **k: compiled.append(f) or jit(f, **k)
    )
    grid = {"variant": ["ppo", my_ppo, "fppo-qp", my_clip_higher], "eps_high": [0.25, 0.4]}
    # A learning rate high enough that ratios pass 1.25, so that the two ε_high differ.
    result = sweep("cartpole", grid, seeds=[4], total_steps=TINY_STEPS, learning_rate=0.03, **tiny)
    assert [s["variant"] for s in result.settings] == [
        "ppo",
        "my-ppo",
        "fppo-qp",
        "my-clip-higher",
        "my-clip-higher",
    ]
    programs = [f for f in compiled if f.__qualname__ == "compile_program.<locals>.run"]
    assert len(programs) == 1  # one program of updates for every run
    assert result.config["runs_per_call"] == 5
    # The user's PPO trains as the built-in beside it, to float rounding (one vmapped program).
    for name, values in result.metrics.items():
        np.testing.assert_allclose(values[1], values[0], rtol=1e-5, atol=1e-6, err_msg=name)
    assert not np.array_equal(
        result.metrics["clip_fraction"][3], result.metrics["clip_fraction"][4]
    )
    assert set(result.config["surrogates"]) == {"my-ppo", "my-clip-higher"}


def test_the_command_line_takes_a_surrogate_by_module_and_its_flags(tiny, tmp_path, capsys):
    shape = ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
    common = ["--steps", str(TINY_STEPS), "--seed", "2", "--quiet", *shape]
    assert main(["train", "--variant", "ppo", "--output", str(tmp_path / "a"), *common]) == 0
    mine = ["train", "--variant", "own_surrogates:my_ppo", "--output", str(tmp_path / "b")]
    assert main([*mine, *common]) == 0
    a, b = ((tmp_path / d / "metrics.csv").read_text().splitlines() for d in "ab")
    assert a == b  # bit for bit, as printed
    # A surrogate's own hyperparameters are flags, and a sweep's grid axes.
    sweep_args = ["sweep", "--variant", "ppo,own_surrogates:my_clip_higher"]
    out = tmp_path / "sweep"
    grid = ["--eps-high", "0.25,0.3", "--seeds", "1", "--output", str(out)]
    assert main([*sweep_args, *grid, "--steps", str(TINY_STEPS), "--quiet", *shape]) == 0
    record = json.loads((out / "sweep.json").read_text())
    assert [s.get("eps_high") for s in record["settings"]] == [None, 0.25, 0.3]
    identity = record["config"]["surrogates"]["my-clip-higher"]
    assert identity["import"] == "own_surrogates:my_clip_higher" and len(identity["digest"]) == 16
    capsys.readouterr()
    assert main(["train", "--variant", "own_surrogates:nothing", *common]) == 2
    assert "own_surrogates has no 'nothing'" in capsys.readouterr().err


def test_a_record_tells_two_functions_under_one_name_apart(tiny):
    # The shape of the sweeps of test_a_user_ppo_trains_bit_for_bit_like_the_builtin.
    run = {"total_steps": TINY_STEPS, **IN_CHUNKS, **tiny}
    first = sweep("cartpole", {"variant": [my_ppo]}, seeds=[0, 1], **run)
    other = surrogate("my-ppo", lambda ratio, advantage: ratio * advantage)
    second = sweep("cartpole", {"variant": [other]}, seeds=[2, 3], **run)
    with pytest.raises(ValueError, match="another surrogate named 'my-ppo'"):
        fppo_jax.merge([first, second])
    same = sweep("cartpole", {"variant": [my_ppo]}, seeds=[2, 3], **run)
    assert len(fppo_jax.merge([first, same]).runs) == 4


def test_a_resumed_run_refuses_another_function_under_the_same_name(tiny, tmp_path):
    train("cartpole", my_ppo, total_steps=TINY_STEPS, checkpoint_dir=tmp_path, **tiny)
    other = surrogate("my-ppo", lambda ratio, advantage: ratio * advantage)
    with pytest.raises(fppo_jax.ConfigMismatch, match="surrogates"):
        train(
            "cartpole", other, total_steps=TINY_STEPS, checkpoint_dir=tmp_path, resume=True, **tiny
        )


def test_one_default_variant_everywhere():
    from fppo_jax.cli.parser import build_parser
    from fppo_jax.core.variants import DEFAULT_VARIANT

    assert fppo_jax.hyperparameters().objective.name == DEFAULT_VARIANT
    assert inspect.signature(train).parameters["variant"].default == DEFAULT_VARIANT
    assert fppo_jax.expand_grid({}) == [{"variant": DEFAULT_VARIANT}]
    assert build_parser().parse_args(["train"]).variant.name == DEFAULT_VARIANT
    assert [s.name for s in build_parser().parse_args(["sweep"]).variant] == [DEFAULT_VARIANT]


def test_an_abbreviated_variant_flag_is_refused_rather_than_losing_its_surrogates_flags(
    module_here, capsys
):
    module_here(
        "here_scaled",
        "import fppo_jax\n"
        "def scaled(ratio, advantage, c):\n"
        "    return c * ratio * advantage\n"
        "mine = fppo_jax.surrogate('here-scaled', scaled, c=1.0)\n",
    )
    with pytest.raises(SystemExit) as exited:
        main(["train", "--vari", "here_scaled:mine", "--c", "0.5"])
    assert exited.value.code == 2
    assert "unrecognized arguments: --vari here_scaled:mine --c 0.5" in capsys.readouterr().err


def test_a_rerun_from_a_record_refuses_a_surrogate_changed_since(tmp_path, capsys):
    from fppo_jax.cli.settings import settings_file

    shape = TrainConfig()
    own = {"my-ppo": my_ppo.identity()}
    run = RunRecord("cartpole", None, "paper", shape, {"variant": "my-ppo"}, surrogates=own)
    record = run.to_json()
    (tmp_path / "config.json").write_text(json.dumps(record))
    assert settings_file(tmp_path / "config.json")["variant"] == "own_surrogates:my_ppo"
    record["surrogates"]["my-ppo"]["digest"] = "0123456789abcdef"  # a function edited since
    (tmp_path / "config.json").write_text(json.dumps(record))
    assert main(["train", "--config", str(tmp_path / "config.json")]) == 2
    assert capsys.readouterr().err == (
        f"fppo-jax: error: {tmp_path / 'config.json'} records another surrogate 'my-ppo' than "
        "own_surrogates:my_ppo is now (recorded digest '0123456789abcdef', now "
        f"{my_ppo.identity()['digest']!r}): restore the one it trained to rerun the run, or "
        "train this one without --config\n"
    )


def _not_finite_past_the_tried_advantages(ratio, advantage):
    # Finite where its declaration tries it (|A| ≤ 2); NaN in value and slope beyond, where
    # training's advantages go at once.
    return ratio * advantage * jnp.where(jnp.abs(advantage) > 2.5, jnp.nan, 1.0)


def test_a_run_that_diverges_names_its_own_surrogate_as_a_cause(tiny):
    mine = surrogate("nan-past-the-trial", _not_finite_past_the_tried_advantages)
    with pytest.raises(
        fppo_jax.TrainingDiverged,
        match=r"Lower the learning rate, check the environment's observations and rewards, or "
        r"check the surrogate 'nan-past-the-trial': its value or slope may not be finite at "
        r"ratios or advantages that training reaches beyond those its declaration tried\.$",
    ):
        train("cartpole", mine, total_steps=TINY_STEPS, **IN_CHUNKS, **tiny)
