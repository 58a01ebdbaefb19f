"""The seed study and the verdicts planned since: its parts, their reports, the sequential rule.

python experiments/studies            # its scripts, each with what it does
python experiments/studies --smoke    # each one run tiny, into a new temporary directory
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import folder_entry_point

# In the order they run: the verdict reads the part the first one trains; the planned verdict
# and the dose-response, which report nothing until every planned run is there, and the
# re-decided verdicts (nothing trained) read the recorded runs and write their reports into the
# temporary directory.
SMOKE = {
    "study.py": "--task cartpole --seeds 0:2 --steps 4096 --variants ppo fppo-lp --results {tmp}",
    "verdict.py": "--results {tmp}",
    "planned_verdict.py": "plans/spo-dpo.json --output {tmp}/spo-dpo.md",
    "dose_response.py": "--output {tmp}/dose_response.md",
    "sequential_rule.py": "--smoke",
    "equivalence_rule.py": "--smoke",
    "redecided.py": "--studies {tmp}/redecided --output {tmp}/redecided.md",
    "tuned_verdict.py": "--output {tmp}/tuned.md",
    "tuned_v2.py": "--output {tmp}/tuned-v2.md",
}

if __name__ == "__main__":
    folder_entry_point(__doc__, Path(__file__).resolve().parent, SMOKE)
