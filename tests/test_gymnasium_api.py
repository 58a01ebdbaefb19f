"""Gymnasium's API as an environment meets it (fppo_jax.envs.gymnasium_api): each call and value
checked, and an environment that breaks the API named with its fault, before compiling where
its first reset and step show it, and where training meets it otherwise."""

import gymnasium
import numpy as np
import pytest
from conftest import TINY
from gymnasium_envs import Broken, Corridor, NaNs, rollouts

import fppo_jax.run.driver
from fppo_jax import train
from fppo_jax.envs import as_environment


def faulty(name: str, reset=None, step=None, space=None) -> type:
    """A Corridor whose reset or step returns what `reset` or `step` make of its own outcome,
    or whose observation space is `space`."""

    def own_reset(self, *, seed=None, options=None):
        out = Corridor.reset(self, seed=seed, options=options)
        return out if reset is None else reset(out)

    def own_step(self, action):
        out = Corridor.step(self, action)
        return out if step is None else step(out)

    body = {"reset": own_reset, "step": own_step}
    return type(name, (Corridor,), body | ({"observation_space": space} if space else {}))


def reward(value):
    return lambda out: (out[0], value, *out[2:])


def observation(value):
    return lambda out: (value, *out[1:])


MISBEHAVING = {
    "raises in reset": (
        faulty("ResetRaises", reset=lambda out: 1 / 0),
        r"ResetRaises: reset raised ZeroDivisionError: division by zero \(at .*test_gymnasium",
    ),
    "raises in step": (Broken, "Broken: step raised RuntimeError: the simulator crashed"),
    "a NaN observation": (NaNs, r"NaNs: step returned a non-finite observation \[nan nan\]"),
    "an infinite observation": (
        faulty("Infinite", reset=lambda out: (out[0] + np.inf, out[1])),
        "Infinite: reset returned a non-finite observation",
    ),
    "an observation of another shape": (
        faulty("Longer", step=observation(np.zeros(3))),
        r"Longer: step returned observations of shape \(3,\), not \(2,\)",
    ),
    "a string observation": (
        faulty("Text", step=observation("position 1")),
        r"Text: step returned the observation 'position 1' \(str\), not numbers",
    ),
    "a NaN reward": (faulty("NaNReward", step=reward(np.nan)), "reward nan .*a finite number"),
    "an infinite reward": (faulty("InfReward", step=reward(-np.inf)), "reward -inf"),
    "an array reward": (
        faulty("ArrayReward", step=reward(np.ones(2))),
        r"ArrayReward: step returned the reward an array of shape \(2,\) \(float64\), not a",
    ),
    "a None reward": (faulty("NoReward", step=reward(None)), r"reward None \(NoneType\)"),
    "a string reward": (faulty("TextReward", step=reward("1")), r"reward '1' \(str\)"),
    "flags of another shape": (
        faulty("Flags", step=lambda out: (*out[:2], np.zeros(2, bool), *out[3:])),
        r"Flags: step returned terminated=an array of shape \(2,\) \(bool\), not a bool",
    ),
    "the old four values from step": (
        faulty("OldStep", step=lambda out: (*out[:2], out[2] or out[3], out[4])),
        r"OldStep: step returned a 4-tuple, not the five values .*old Gym API",
    ),
    "a bare observation from reset": (
        faulty("BareReset", reset=lambda out: out[0]),
        r"BareReset: reset returned an array of shape \(2,\) \(float32\), not the pair",
    ),
    "an empty observation space": (
        faulty("Empty", space=gymnasium.spaces.Box(0.0, 1.0, (0,), np.float32)),
        r"Empty: its observation space Box\(.*\) is empty",
    ),
}


@pytest.mark.parametrize("env, message", MISBEHAVING.values(), ids=MISBEHAVING.keys())
def test_an_environment_that_breaks_the_api_is_named_with_its_fault_before_compiling(
    env, message, monkeypatch
):
    monkeypatch.setattr(fppo_jax.run.driver, "compile_program", lambda *_: pytest.fail("compiled"))
    with pytest.raises(ValueError, match=message):
        train(env, "ppo", total_steps=256, **TINY)


def test_faults_after_the_first_step_stop_training_naming_the_environment():
    class LaterNaN(Corridor):
        def step(self, action):
            obs, reward, terminated, truncated, info = super().step(action)
            return obs, np.nan if self.steps == 4 else reward, terminated, truncated, info

    with pytest.raises(Exception, match=r"LaterNaN: step returned the reward nan"):
        train(LaterNaN, "ppo", total_steps=256, **TINY)
    vector = gymnasium.vector.SyncVectorEnv([LaterNaN, LaterNaN])
    with pytest.raises(Exception, match=r"SyncVectorEnv.*: step returned the reward .*2 finite"):
        rollouts(as_environment(vector), [0, 0], 5)
