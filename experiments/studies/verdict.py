"""The seed study's verdict: does FPPO beat PPO? Every recorded part, merged, with its statistics.

    python experiments/studies/verdict.py                       # results/study.md and its figures
    # a smoke run's parts (study.py --results)
    python experiments/studies/verdict.py --results /tmp/smoke

Reads every part that `study.py` recorded under <results>/study/<task>/<protocol>/. The report's
body is the library's own: `fppo_jax.study` over those parts (reused, nothing trained), one study
per family of comparisons (a study has one seed schedule), each kept whole with its plan and
decisions in <results>/study-command/<family>/. After it, what only this study has: the test
planned before any part ran (Mann–Whitney, Holm over each protocol's planned comparisons), the
paper's Table 1 beside the same statistic here, the exploratory variants and the escape speed.
Writes <results>/study.md and <results>/study/curves_*.png. Decided before any part ran, and
stated in the report: the primary endpoint is each run's final return (its last-100-episode
average after the last update), the secondary the area under its learning curve (the average
return averaged over updates, for "fast"); the paper's max average return is shown beside them,
with an interval for its gap to PPO, since it is biased upward by a different amount per variant.
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from study import PROTOCOLS as PROTOCOL_SETTINGS

import fppo_jax
from fppo_jax import SweepResult, merge
from fppo_jax.analysis.plots import plot_curves
from fppo_jax.analysis.report_kit import LEVEL, interval_cell, mann_whitney_verdicts
from fppo_jax.envs import MUJOCO_TASKS
from fppo_jax.run.results import labels, max_average_return
from fppo_jax.stats import statistics

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    CLASSIC_TASKS,
    ESCAPE_FRACTIONS,
    ESCAPE_VARIANTS,
    PAPER_VARIANTS,
    RESULTS,
    TABLE1,
    argument_parser,
    by_variant,
    read_fractions,
    read_run_record,
    recorded_parts,
    write_result,
)
from edges import EDGE_SEEDS, edge, edge_note, outcome

BASELINE = "ppo"
CHALLENGERS = ("fppo-lp", "fppo-qp")
# What the study sets out to record: (variants, seeds per variant, protocols) per task.
PLAN = {
    **{task: (PAPER_VARIANTS, 50, ("paper", "unnormalised")) for task in CLASSIC_TASKS},
    **{task: (("ppo", "fppo-lp", "fppo-qp"), 20, ("paper",)) for task in MUJOCO_TASKS},
}
# Run on the MuJoCo tasks where time allows, and reported as exploratory: no planned comparison.
EXPLORATORY, EXPLORATORY_SEEDS = ("tr-ppo", "ppo-rb"), 10
PROTOCOLS = {
    "paper": "the project's protocol: observation and reward normalisation",
    "unnormalised": "baselines' classic-control protocol: no normalisation",
}
# The planned comparisons as the library's study takes them, one family per seed schedule and
# protocol: its folder under study-command/, its heading, tasks, seeds and protocol.
FAMILIES = (
    ("mujoco", "The MuJoCo tasks", MUJOCO_TASKS, 20, "paper"),
    ("classic", "The classic tasks", CLASSIC_TASKS, 50, "paper"),
    ("classic-unnormalised", "The classic tasks", CLASSIC_TASKS, 50, "unnormalised"),
)
REPOSITORY = Path(__file__).resolve().parents[2]
DPI = 80


def recorded(results: Path, task: str, protocol: str) -> tuple[SweepResult | None, list[dict]]:
    """The merged parts of `task` under `protocol` that ran this study's variants (parts of
    other studies, such as SPO's and DPO's, share the folders), and each one's run record."""
    studied = {*PLAN[task][0], *EXPLORATORY}
    parts = recorded_parts(results / "study" / task / protocol)
    parts = {d: r for d, r in parts.items() if studied & {s["variant"] for s in r.settings}}
    if not parts:
        return None, []
    records = [read_run_record(d) for d in parts]
    return merge(list(parts.values())), records


def run_counts(result: SweepResult | None, variants: tuple[str, ...]) -> dict[str, int]:
    """How many runs of each of `variants` the merged parts hold, diverged ones included."""
    index = {} if result is None else by_variant(result)
    return {v: result.setting_run_count(index[v]) if v in index else 0 for v in variants}


def planned_comparisons(protocol: str) -> list[tuple[str, str]]:
    """The family the study set out to test under `protocol`: each challenger against PPO on
    each task's final returns."""
    return [
        (task, variant)
        for task, (variants, _, protocols) in PLAN.items()
        if protocol in protocols
        for variant in CHALLENGERS
        if variant in variants
    ]


def holm_adjusted(results: dict[str, SweepResult], protocol: str) -> dict[tuple[str, str], float]:
    """Holm-adjusted p-values of Mann–Whitney's test of P(challenger > PPO) = ½ on final
    returns, over the protocol's whole planned family; a comparison not recorded yet enters
    as p = 1, so the adjustment can only fall as the study fills in."""
    family = planned_comparisons(protocol)
    none = (np.array([]), np.array([]))  # not recorded yet: untested
    compared = []
    for task, variant in family:
        result = results.get(task)
        index = by_variant(result) if result is not None else {}
        if {variant, BASELINE} <= set(index):
            final = result.scores("final")
            compared.append((final[index[variant]], final[index[BASELINE]]))
        else:
            compared.append(none)
    verdicts = mann_whitney_verdicts(compared)
    return {key: verdict.holm for key, verdict in zip(family, verdicts, strict=True)}


def ordered(result: SweepResult) -> dict[str, int]:
    """Each variant's setting in `result`, the exploratory variants last."""
    return dict(sorted(by_variant(result).items(), key=lambda item: item[0] in EXPLORATORY))


def task_section(
    task: str,
    protocol: str,
    result: SweepResult,
    records: list[dict],
    adjusted: dict[tuple[str, str], float],
) -> list[str]:
    """`task`'s section under `protocol`: its parts, each variant's runs beside the paper's
    Table 1, and each variant against PPO (the planned ones with their Holm p, `adjusted`)."""
    lines = runs_table(task, protocol, result, records)
    if BASELINE not in by_variant(result):
        return [*lines, ""]
    return [*lines, *against_baseline(task, protocol, result, adjusted), ""]


def runs_table(task: str, protocol: str, result: SweepResult, records: list[dict]) -> list[str]:
    """`task`'s parts under `protocol` (their runs, hours, machines and commits) and each
    variant's IQMs, spread and max average return beside the paper's."""
    index, names = ordered(result), labels(result.settings)
    final, area = result.scores("final"), result.scores("auc")
    wall = sum(r["wall_seconds"] for r in records)
    commits = sorted({r["commit"] for r in records})
    # Parts may run on different machines: the same code, rounded differently by each
    # processor, so each seed is still a sample of one protocol.
    machines = list(dict.fromkeys(r["machine"] for r in records))
    lines = [
        f"### {task}, {protocol} protocol",
        "",
        f"{len(records)} part{'s' if len(records) > 1 else ''}, {len(result.runs)} runs of "
        f"{result.config['total_steps']:,} env steps, {wall / 3600:.2f} h in all on "
        f"{' and on '.join(machines)}; commit {', '.join(c[:12] for c in commits)}.",
        "",
        "| variant | runs | IQM final [95% CI] | IQM AUC [95% CI] | sample std final "
        "| max average return ± sample std | paper (Table 1) |",
        "|---|---|---|---|---|---|---|",
    ]
    for variant, i in index.items():
        best, std, _ = max_average_return(result.setting_metrics(i)["average_return"])
        paper = TABLE1[task][PAPER_VARIANTS.index(variant)]
        lines.append(
            f"| {names[i]} | {result.setting_seeds(i)} "
            f"| {interval_cell(statistics.interval(final[i]), '.1f')} "
            f"| {interval_cell(statistics.interval(area[i]), '.1f')} "
            f"| {statistics.sample_std(final[i]):.1f} | {best:.1f} ± {std:.1f} | {paper} |"
        )
    return lines


def against_baseline(
    task: str, protocol: str, result: SweepResult, adjusted: dict[tuple[str, str], float]
) -> list[str]:
    """Each variant against PPO on `task`: P(variant > PPO) and its outcome, the planned
    comparisons' Holm p (`adjusted`), and the paper's gap beside the one measured here."""
    index, names = ordered(result), labels(result.settings)
    final, area, base = result.scores("final"), result.scores("auc"), index[BASELINE]
    lines = [
        "",
        f"Against {BASELINE}: P(variant > {BASELINE}) on final returns and on AUC, the "
        "difference in IQM of final returns, and the difference in the paper's statistic "
        "beside the paper's own gap (all 95% bootstrap CIs), also each as a share of its own "
        "PPO's max average return, since the paper's returns and these are on different "
        "scales; for the planned comparisons, "
        f"the Holm-adjusted p over the {len(adjusted)} of the {protocol} protocol.",
        "",
        "| variant | P(> ppo), final | outcome | Holm p | P(> ppo), AUC | Δ IQM final "
        "| Δ max average return | paper's Δ | paper's Δ in the CI "
        "| Δ max average return, share of PPO's | paper's Δ, share of its PPO's | in the CI |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    curves = {v: result.setting_metrics(i)["average_return"] for v, i in index.items()}
    scale = abs(max_average_return(curves[BASELINE])[0])
    edges: list[str] = []
    for variant, i in index.items():
        if i == base:
            continue
        on_final = statistics.compare(final[i], final[base])
        on_area = statistics.compare(area[i], area[base])
        gap = statistics.max_average_difference(curves[variant], curves[BASELINE])
        probability = on_final["probability_of_improvement"]
        at_edge = edge(
            probability,
            lambda seed, i=i: statistics.compare(final[i], final[base], seed=seed)[
                "probability_of_improvement"
            ],
            0.5,
        )
        if at_edge is not None:
            edges.append(f"{names[i]}'s P(> {BASELINE}), final: {at_edge.text()}")
        holm = adjusted.get((task, variant))
        lines.append(
            f"| {names[i]} | {interval_cell(probability, '.2f')} | {outcome(probability, at_edge)} "
            f"| {'–' if holm is None else f'{holm:.2f}'} "
            f"| {interval_cell(on_area['probability_of_improvement'], '.2f')} "
            f"| {interval_cell(on_final['iqm_difference'], '.1f')} "
            + paper_gap_cells(task, variant, gap, scale)
        )
    return [*lines, *edge_note(edges, "0.5")]


def paper_gap_cells(task: str, variant: str, gap: tuple[float, float, float], scale: float) -> str:
    """The gap in max average return to PPO measured here (`gap`) beside the paper's, in
    return and as a share of each one's PPO (`scale`: PPO's here), with whether the paper's
    lies in the interval, as the table's last cells."""
    paper_base = TABLE1[task][PAPER_VARIANTS.index(BASELINE)]
    paper_gap = TABLE1[task][PAPER_VARIANTS.index(variant)] - paper_base
    inside = "yes" if gap[1] <= paper_gap <= gap[2] else "no"
    share = tuple(g / scale for g in gap)
    paper_share = paper_gap / abs(paper_base)
    inside_share = "yes" if share[1] <= paper_share <= share[2] else "no"
    return (
        f"| {interval_cell(gap, '.1f')} | {paper_gap:+.1f} | {inside} | {percent(share)} "
        f"| {paper_share:+.0%} | {inside_share} |"
    )


def percent(values: tuple[float, ...]) -> str:
    """A share and its interval in percent: ``-5% [-12%, +3%]``."""
    point, low, high = values
    return f"{point:+.0%} [{low:+.0%}, {high:+.0%}]"


def library_reports(results: Path) -> list[str]:
    """Each family's report by the library's own study, `fppo_jax.study` with every run taken
    from the recorded parts and none trained, written whole in <results>/study-command/<family>/
    and returned with its headings put under this report's."""
    lines = []
    for folder, heading, tasks, seeds, protocol in FAMILIES:
        output = results / "study-command" / folder
        # From the repository, so the plan names the parts' folder as the command line would.
        with contextlib.chdir(REPOSITORY):
            fppo_jax.study(
                tasks,
                CHALLENGERS,
                BASELINE,
                output=output,
                reuse=os.path.relpath(results / "study"),
                groups=0,
                max_seeds=seeds,
                group_size=seeds,
                progress=False,
                **PROTOCOL_SETTINGS[protocol],
            )
        report = (output / "report.md").read_text().splitlines()[1:]  # its title is this one's
        lines += [
            f"### {heading}, {seeds} seeds ({protocol} protocol)",
            "",
            f"Its plan, decisions and figures: `{output.relative_to(results)}/`.",
            *(f"##{line}" if line.startswith("#") else line for line in report),
            "",
        ]
    return lines


def escape_section(path: Path, label: str) -> list[str]:
    """The escape-speed effect on the same data (escape_speed.py's records at `path`): per
    seed, FPPO's share of the batch in R+ ∪ R- after the last epoch minus PPO's, averaged over
    the update points; the mean of those paired differences over seeds, with its CI."""
    if not path.exists():
        return []
    lines = [
        f"## The escape speed on the same data ({label})",
        "",
        "Per seed: the share of the batch left in R+ ∪ R- after the update's last epoch under "
        "the variant minus under PPO, from the same parameters, batch and minibatch order, "
        "averaged over the update points; the mean over seeds with a 95% bootstrap CI. Below "
        "zero, the variant leaves fewer samples in the negatively optimised regions.",
        "",
        "| task | seeds | FPPO-LP − PPO, points of % [95% CI] | FPPO-QP − PPO [95% CI] |",
        "|---|---|---|---|",
    ]
    edges = []
    for task, values in read_fractions(path).items():  # [seed, point, variant, epoch]
        last = values[..., -1].mean(axis=1) * 100  # [seed, variant], in %
        cells = []
        for variant in ("fppo-lp", "fppo-qp"):
            paired = last[:, ESCAPE_VARIANTS.index(variant)] - last[:, 0]
            difference = statistics.interval(paired, "mean")
            cells.append(interval_cell(difference, ".2f"))
            at_edge = edge(
                difference,
                lambda seed, paired=paired: statistics.interval(paired, "mean", seed=seed),
                0.0,
            )
            if at_edge is not None:
                edges.append(f"{task} {variant.upper()}: {at_edge.text()}")
        lines.append(f"| {task} | {len(last)} | {' | '.join(cells)} |")
    return [*lines, *edge_note(edges, "0"), ""]


def figures(results: dict[str, SweepResult], out: Path, protocol: str) -> Path:
    """Each task's learning curves under `protocol`: IQM with its 95% bootstrap band."""
    tasks = list(results)
    columns = min(3, len(tasks))
    rows = -(-len(tasks) // columns)
    fig, axes = plt.subplots(
        rows, columns, figsize=(3.6 * columns, 2.8 * rows), layout="constrained", squeeze=False
    )
    for ax, task in zip(axes.flat, tasks, strict=False):
        plot_curves(results[task], band="iqm", ax=ax)
        counts = run_counts(results[task], tuple(by_variant(results[task]))).values()
        low, high = min(counts), max(counts)
        seeds = f"{low}" if low == high else f"{low}–{high}"
        ax.set_title(f"{task} ({seeds} seeds; IQM, 95% CI)", fontsize="medium")
        ax.legend(fontsize="x-small")
    for ax in axes.flat[len(tasks) :]:
        ax.set_visible(False)
    path = out / f"curves_{protocol}.png"
    fig.savefig(path, dpi=DPI, pil_kwargs={"optimize": True})
    plt.close(fig)
    return path


def preamble() -> list[str]:
    """The report's title and what it holds: its endpoints, statistics, planned test and runs."""
    return [
        "# Does FPPO beat PPO? The seed study",
        "",
        "Written by `python experiments/studies/verdict.py` from the parts that "
        "`experiments/studies/study.py` recorded (each part's command is in its `run.json`). "
        "Its body is the library's own report: `fppo_jax.study` (as `fppo-jax study --reuse "
        "experiments/results/study --groups 0`) takes every run from those parts, trains "
        "none, decides each comparison by its group-sequential test and reports what each "
        "interval rules out and how soon the runs reach PPO's level, one study per family of "
        "comparisons (a study has one seed schedule). After it, what only this study has: the "
        "test planned before any of its parts ran, the paper's Table 1 beside the same "
        "statistic here, the exploratory variants, and the escape speed.",
        "",
        "- Endpoints, fixed before the study ran: **final return** (primary: each run's "
        "last-100-episode average return after its last update) and the **area under the "
        "curve** (secondary: the average return averaged over updates). The paper's max "
        "average return (the maximum over updates of the seed-mean curve) is shown beside "
        "them; it is biased upward, by an amount that differs between variants.",
        "- Statistics (`fppo_jax.stats.statistics`, after Agarwal et al. 2021): IQM with a 95% "
        "percentile bootstrap CI (2,000 resamples, seeded); P(X > Y) + ½ P(X = Y) over all "
        "pairs of runs (probability of improvement) with a bootstrap CI that resamples both "
        "variants' runs; `outcome` is *better* or *worse* where that CI excludes 0.5, "
        "*not resolved* where it holds 0.5, one comparison at a time, and *at the edge* where "
        "the bound nearest 0.5 lies within the bootstrap's Monte Carlo error of it (the range "
        f"of that bound over {EDGE_SEEDS} resampling seeds), so that the interval neither "
        "holds nor excludes 0.5 to the bootstrap's resolution; the same for any interval "
        "below said to hold or exclude 0.",
        "- The planned comparisons, FPPO-LP and FPPO-QP against PPO on each task's final "
        "returns, are tested as planned, as a family: Mann–Whitney's U test of P = ½, each p-value "
        "adjusted by Holm's step-down method over every planned comparison of its protocol "
        f"(one not recorded yet counts as p = 1). A *Holm p* below {LEVEL:g} is a difference that "
        "survives the number of comparisons made; TR-PPO's and PPO-RB's rows are exploratory "
        "and carry none.",
        "- Runs: seed s starts from `jax.random.key(s)`; Table 2's α and k; the `paper` preset "
        "(8 envs × 256 steps, 32 minibatches × 10 epochs, Adam 3e-4, annealed on MuJoCo); MuJoCo "
        "tasks on native MuJoCo (envpool, gym's v3 tasks; Reacher v2), so absolute returns are "
        "not the paper's (MuJoCo 1.5, gym v2).",
        "",
    ]


def merged_parts(
    results: Path,
) -> tuple[dict[str, dict[str, SweepResult]], list[tuple[str, str, list[dict]]]]:
    """Every task's recorded parts under each protocol, merged (by protocol, then task), and
    each (task, protocol) recorded, with its parts' run records."""
    merged: dict[str, dict[str, SweepResult]] = {p: {} for p in PROTOCOLS}
    parts = []
    for task, (_, _, protocols) in PLAN.items():
        for protocol in protocols:
            result, records = recorded(results, task, protocol)
            if result is not None:
                merged[protocol][task] = result
                parts.append((task, protocol, records))
    return merged, parts


def standing_lines(merged: dict[str, dict[str, SweepResult]]) -> list[str]:
    """Where the study stands: what is complete, what is still to run and what of the
    exploratory variants ran."""
    done, missing = [], []
    for task, (variants, seeds, protocols) in PLAN.items():
        for protocol in protocols:
            result = merged[protocol].get(task)
            short = {v: n for v, n in run_counts(result, variants).items() if n < seeds}
            label = f"{task} ({protocol})"
            if result is None:
                missing.append(f"{label}: not started")
            elif short:
                missing.append(
                    f"{label}: " + ", ".join(f"{v} {n} of {seeds} seeds" for v, n in short.items())
                )
            else:
                done.append(label)
    explored = []
    for task in MUJOCO_TASKS:
        counts = run_counts(merged["paper"].get(task), EXPLORATORY)
        if any(counts.values()):
            explored.append(f"{task} ({', '.join(f'{v} {n}' for v, n in counts.items())})")
    return [
        "## Where the study stands",
        "",
        f"- Complete: {', '.join(done) or 'nothing yet'}.",
        f"- Still to run: {'; '.join(missing) or 'nothing'}.",
        f"- Exploratory, where time allowed ({' and '.join(EXPLORATORY)} at "
        f"{EXPLORATORY_SEEDS} seeds on the MuJoCo tasks): {'; '.join(explored) or 'none yet'}.",
        "",
    ]


def figure_lines(results: Path, merged: dict[str, dict[str, SweepResult]]) -> list[str]:
    """The figures: each protocol's learning curves, drawn into <results>/study/, and the
    library's studies' own."""
    out = results / "study"
    out.mkdir(parents=True, exist_ok=True)
    pictures = [f"study/{figures(runs, out, p).name}" for p, runs in merged.items() if runs]
    for folder, *_ in FAMILIES:
        for name in ("improvement.png", "profiles.png"):
            if (results / "study-command" / folder / name).exists():
                pictures.append(f"study-command/{folder}/{name}")
    return [
        "## Figures",
        "",
        *(f"![{p.removesuffix('.png').replace('/', ', ')}]({p})" for p in pictures),
    ]


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--results", type=Path, default=RESULTS, help="where the parts are")
    args = parser.parse_args()
    merged, parts = merged_parts(args.results)
    adjusted = {p: holm_adjusted(results, p) for p, results in merged.items()}
    sections = [
        line
        for task, protocol, records in parts
        for line in task_section(
            task, protocol, merged[protocol][task], records, adjusted[protocol]
        )
    ]
    lines = [
        *preamble(),
        *standing_lines(merged),
        "## The library's report",
        "",
        *library_reports(args.results),
        "## Per task: the planned test and the paper's numbers",
        "",
        *sections,
        *escape_section(
            args.results / ESCAPE_FRACTIONS,
            "`results/escape_speed/`, as `results/escape_speed.md` records it",
        ),
        *figure_lines(args.results, merged),
    ]
    path = args.results / "study.md"
    write_result(path, lines)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
