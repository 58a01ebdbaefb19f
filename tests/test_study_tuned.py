"""fppo_jax.analysis.study_tuned: a study takes a tune's settings only from a finished tune."""

import pytest
from helpers import TUNE_ARMS as ARMS
from helpers import TUNE_SMALL as SMALL

from fppo_jax.analysis.studies import study
from fppo_jax.analysis.tuning import tune
from fppo_jax.errors import InvalidInput


def test_a_tune_not_finished_is_no_source_of_settings(tmp_path):
    tune("cartpole", ARMS, output=tmp_path / "tune", rungs=0, **SMALL)
    with pytest.raises(InvalidInput, match="not finished"):
        study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", tuned=tmp_path / "tune")
