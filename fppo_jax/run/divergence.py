"""What a single run raises when it diverges: its loss or parameters became NaN or infinite, at
an update the trainer records (a sweep's runs go on, each with the update it diverged at)."""

from __future__ import annotations

from fppo_jax.errors import FppoError


class TrainingDiverged(FppoError, FloatingPointError):
    """The loss or the parameters became NaN or infinite."""

    def __init__(
        self,
        update: int,
        env_steps: int,
        checkpoint: str | None = None,
        surrogate: str | None = None,
    ):
        """`update` counts from 1, as the progress lines do; `checkpoint` says where the last
        good checkpoint is, if any; `surrogate` names the run's surrogate if it is one's own."""
        self.update, self.env_steps = update, env_steps
        kept = f" {checkpoint}." if checkpoint else ""
        advice = "Lower the learning rate, or check the environment's observations and rewards"
        if surrogate:  # its declaration tried it on ratios 0.25 … 4 only: training reaches others
            advice = (
                "Lower the learning rate, check the environment's observations and rewards, or "
                f"check the surrogate {surrogate!r}: its value or slope may not be finite at "
                "ratios or advantages that training reaches beyond those its declaration tried"
            )
        super().__init__(
            f"training diverged at update {update} (after {env_steps:,} env steps): the loss or "
            f"the parameters became NaN or infinite.{kept} {advice}."
        )
