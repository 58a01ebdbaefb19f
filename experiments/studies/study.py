"""Does FPPO beat PPO? One part of the seed study: a task's variants × a range of seeds, recorded.

    python experiments/studies/study.py --task hopper --seeds 0:10  # PPO, FPPO-LP, FPPO-QP
    python experiments/studies/study.py \
        --task cartpole --seeds 0:50 --variants all --protocol unnormalised
    python experiments/studies/study.py --task reacher --seeds 0:2 --steps 8192 --results /tmp/smoke
    python experiments/studies/study.py --task hopper --seeds 0:2 --plan plans/dose-response.json
    python experiments/studies/study.py --task swimmer --seeds 0:5 --plan plans/baseline-shape.json

A part is one sweep (one compiled program) of `--variants` × `--seeds` on `--task`, with the
`paper` preset, Table 2's α and k and the paper's budget (100k steps on the classic tasks, 1M on
MuJoCo). Run seed s starts from ``jax.random.key(s)`` whatever else the part holds, so parts
with disjoint seeds or other variants are samples of one study and are merged by what reads
them (``verdict.py``, beside this script). Protocols: ``paper`` is the project's default
(observation and reward normalisation everywhere); ``unnormalised`` is baselines'
classic-control protocol (no VecNormalize: baselines wraps only its MuJoCo runs).

With ``--plan PLAN`` the part is the plan's own, recorded under
<results>/<plan's name>/<task>/<protocol>/: every dose of its variants in one sweep (its
``doses``), or its ``candidates`` with its ``settings`` (such as another rollout shape).

Each part goes to <results>/study/<task>/<protocol>/<part>/ (`curves.csv`, `sweep.json`,
`run.json` with the machine, date, wall time, command and the commit it ran at), written into a
fresh directory and renamed into place whole. A part already recorded is refused unless
`--force`: the study's records are never replaced by accident. So is, before it trains, a part
that would hold a run another part of the same task and protocol holds (a seed of a variant
both have): the parts could not be merged.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from fppo_jax import sweep
from fppo_jax.core.checks import parse_seeds
from fppo_jax.core.variants import VARIANTS
from fppo_jax.envs import MUJOCO_TASKS

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    CLASSIC_TASKS,
    PAPER_VARIANTS,
    RECORDED_METRICS,
    add_record_flags,
    argument_parser,
    refuse_to_replace,
    write_run_record,
)

STUDIED = ("ppo", "fppo-lp", "fppo-qp")
PROTOCOLS = {
    "paper": {},
    "unnormalised": {"normalize_observations": False, "normalize_rewards": False},
}


def part_name(variants: list[str], seeds: list[int]) -> str:
    contiguous = seeds == list(range(seeds[0], seeds[0] + len(seeds)))
    span = f"{seeds[0]}-{seeds[-1]}" if contiguous else ",".join(map(str, seeds))
    return f"seeds-{span}_{'+'.join(variants)}"


def part_runs(name: str) -> tuple[list[str], list[int]] | None:
    """The variants and seeds of the part :func:`part_name` named `name`; None for a name it
    does not make (a part being written, say)."""
    prefix, _, rest = name.partition("seeds-")
    span, _, variants = rest.partition("_")
    if prefix or not variants:
        return None
    try:
        if "," in span or "-" not in span:
            seeds = [int(seed) for seed in span.split(",")]
        else:
            first, last = span.split("-")
            seeds = list(range(int(first), int(last) + 1))
    except ValueError:
        return None
    return variants.split("+"), seeds


def overlapping_parts(folder: Path, variants: list[str], seeds: list[int]) -> list[str]:
    """The parts recorded in `folder` (a task's protocol) other than the one `variants` ×
    `seeds` makes that hold one of its runs: a seed of a variant both have, which would keep the
    study's parts from being merged."""
    clashes = []
    own = part_name(variants, seeds)
    for part in sorted(folder.iterdir()) if folder.is_dir() else []:
        runs = part_runs(part.name)
        if part.name == own or runs is None:
            continue
        shared = [v for v in variants if v in runs[0]]
        both = sorted(set(seeds) & set(runs[1]))
        if shared and both:
            clashes.append(f"{part.name} ({', '.join(shared)} at seeds {_listed(both)})")
    return clashes


def _listed(seeds: list[int]) -> str:
    return ", ".join(map(str, seeds[:5])) + (", …" if len(seeds) > 5 else "")


def planned_sweep(plan: dict) -> tuple[dict[str, list], dict[str, Any]]:
    """The grid and the fixed settings of `plan`'s part: every dose of its variants (``doses``:
    each one's values), or its ``candidates`` with its ``settings``."""
    if "doses" not in plan:
        return {"variant": list(plan["candidates"])}, plan.get("settings", {})
    grid: dict[str, list] = {"variant": list(plan["doses"])}
    for values in plan["doses"].values():
        if isinstance(values, dict):
            grid.update({name: v for name, v in values.items() if isinstance(v, list)})
    return grid, {}


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--task", required=True, choices=[*CLASSIC_TASKS, *MUJOCO_TASKS])
    parser.add_argument("--seeds", type=parse_seeds, required=True, help="20, 10:20 or 0,3,7")
    parser.add_argument(
        "--variants",
        nargs="+",
        default=list(STUDIED),
        help=f"variants, or 'all' for {', '.join(PAPER_VARIANTS)} (default: {', '.join(STUDIED)})",
    )
    parser.add_argument(
        "--plan", type=Path, help="a plan's own part (plans/dose-response.json, say)"
    )
    parser.add_argument("--protocol", default="paper", choices=list(PROTOCOLS))
    parser.add_argument("--steps", type=int, help="env steps per run (default: the paper's)")
    parser.add_argument("--backend", default=None, help="default: native on MuJoCo, else auto")
    parser.add_argument("--chunk", type=int, help="runs per compiled call (default: automatic)")
    add_record_flags(parser)
    args = parser.parse_args()
    variants = list(PAPER_VARIANTS) if args.variants == ["all"] else args.variants
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        parser.error(f"unknown variant {', '.join(unknown)}; valid: {', '.join(VARIANTS)}")
    backend = args.backend or ("native" if args.task in MUJOCO_TASKS else "auto")

    grid: dict[str, list] = {"variant": variants}
    folder = args.results / "study" / args.task / args.protocol
    settings: dict[str, Any] = {}
    if args.plan:
        plan = args.plan if args.plan.exists() else Path(__file__).resolve().parents[1] / args.plan
        grid, settings = planned_sweep(json.loads(plan.read_text()))
        variants = [plan.stem]
        folder = args.results / plan.stem.replace("-", "_") / args.task / args.protocol
    directory = folder / part_name(variants, args.seeds)
    refuse_to_replace([directory], args.force)
    clashes = overlapping_parts(folder, variants, args.seeds)
    if clashes:
        sys.exit(
            f"{folder} holds these runs already, in {'; '.join(clashes)}: a study's parts hold "
            "each run once (merging refuses a run two parts hold); choose other seeds, or "
            "remove that part to record it again"
        )
    print(f"part: {directory}", flush=True)
    start = time.perf_counter()
    result = sweep(
        args.task,
        grid,
        seeds=args.seeds,
        total_steps=args.steps,
        chunk=args.chunk,
        backend=backend,
        progress=True,
        **PROTOCOLS[args.protocol],
        **settings,
    )
    wall = time.perf_counter() - start
    directory.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".part-", dir=directory.parent))
    result.write(staging, metrics=RECORDED_METRICS)
    write_run_record(staging, wall, protocol=args.protocol)
    if directory.exists():  # --force
        shutil.rmtree(directory)
    staging.rename(directory)
    print(f"wrote {directory} ({wall:,.0f} s)", flush=True)


if __name__ == "__main__":
    main()
