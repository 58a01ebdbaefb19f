"""Profiles: where an update's time goes, by part, by operation, and by what the trainer adds.

python experiments/profiles            # its scripts, each with what it does
python experiments/profiles --smoke    # each one run tiny, into a new temporary directory
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import folder_entry_point

SMOKE = {
    "profile_update.py": "--repeats 1 --results {tmp}",
    "profile_ops.py": "--seeds 2 --steps 4096 --results {tmp}",
    "profile_vmap.py": "--seeds 2 --steps 4096 --repeats 1 --results {tmp}",
    "profile_mujoco.py": "--env reacher --num-envs 8 --updates 1 --repeats 1 --results {tmp}",
}

if __name__ == "__main__":
    folder_entry_point(__doc__, Path(__file__).resolve().parent, SMOKE)
