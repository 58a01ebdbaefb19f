"""A run that diverges (fppo_jax.run.divergence): stopped at its first update whose loss or
parameters are not finite, with an error naming the update, the last good checkpoint and,
for a surrogate of one's own, the surrogate."""

import pytest
from helpers import NaNRewardAfter

from fppo_jax import TrainingDiverged, train
from fppo_jax.errors import FppoError


def test_divergence_stops_with_the_update(tiny):
    with pytest.raises(TrainingDiverged, match="diverged at update 1 \\(after 128 env steps\\)"):
        train("cartpole", "ppo", total_steps=512, learning_rate=1e30, **tiny)


def test_nan_rewards_stop_training_with_the_update(tiny):
    with pytest.raises(TrainingDiverged, match="at update 1 "):
        train(NaNRewardAfter(5), "fppo-lp", total_steps=512, **tiny)


def test_the_error_names_the_update_the_checkpoint_and_one_s_own_surrogate():
    plain = TrainingDiverged(3, 384)
    assert (plain.update, plain.env_steps) == (3, 384)
    assert str(plain) == (
        "training diverged at update 3 (after 384 env steps): the loss or the parameters became "
        "NaN or infinite. Lower the learning rate, or check the environment's observations and "
        "rewards."
    )
    kept = TrainingDiverged(3, 384, "The last good checkpoint, at update 2, is in /runs/a")
    assert "infinite. The last good checkpoint, at update 2, is in /runs/a. Lower" in str(kept)
    own = str(TrainingDiverged(3, 384, surrogate="mine"))
    assert "or check the surrogate 'mine': its value or slope may not be finite" in own
    assert isinstance(plain, FppoError) and isinstance(plain, FloatingPointError)
