"""Reproduce the paper: Table 1's classic and MuJoCo rows, Fig. 6, the escape speed, the figures.

python experiments/paper            # its scripts, each with what it does
python experiments/paper --smoke    # each one run tiny, into a new temporary directory
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import folder_entry_point

REACHER = "--backend native --tasks reacher --seeds 1"
SMOKE = {  # in the order they run: the figures draw what the others wrote
    "table1_classic.py": "--tasks cartpole --seeds 1 --steps 4096 "
    "--output {tmp}/table1_classic.md --curves {tmp}/table1_classic",
    "table1_mujoco.py": f"{REACHER} --variants ppo fppo-lp --steps 4096 --results {{tmp}}",
    "ablation.py": f"{REACHER} --steps 2048 --results {{tmp}}",
    "escape_speed.py": "--tasks cartpole --seeds 1 --points 2 4 --results {tmp}",
    "figures.py": "--records {tmp} --out {tmp}/figures",
}

if __name__ == "__main__":
    folder_entry_point(__doc__, Path(__file__).resolve().parent, SMOKE)
