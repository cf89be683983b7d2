"""The baselines page from the studies of ``docs/experiments/baselines.sh`` (issue 33): does the early warning make a
good optimiser safe?

    python docs/experiments/baselines_page.py [--runs runs/baselines] [--page docs/results/baselines.md]
                                              [--figures docs/results/baselines]

Every run folder under ``RUNS/<walker>/<study>/`` is read (``records.jsonl``, ``scenario.yaml``, ``summary.json``);
runs are grouped by what they are (the proposer, its gate and settings, the vigilance), whatever study holds them.
Only completed runs enter a number; the others are listed. The page's numbers, claims and figures are all computed
here: the claims are a family fixed below (:func:`claims`) before any run was read, each with its test and Holm's
adjustment over the family (:mod:`sfl_brain.report.stats`); a claim whose adjusted p is not below 0.05 is shown as *not
shown*, and the text says so. ``numbers.json`` beside the figures holds every run's metrics.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.recording.metrics import DISTINCT, K_GOOD, safe_learning  # noqa: E402
from sfl_brain.recording.records import read_records, run_status  # noqa: E402
from sfl_brain.report import stats  # noqa: E402
from sfl_brain.report.study import (  # noqa: E402
    Claim,
    RunMetrics,
    StudySettings,
    bounded_cell,
    censored_cell,
    claims_table,
    study_figures,
    tradeoff_figure,
)

#: the walkers, their scenario's trial budget and the vigilance the gate runs at (the scenario's own)
WALKERS = {
    "planar": {"title": "The planar reflex walker, E3.2 setting (flat, 10x10 maps, no QARL; 200 trials)", "s_vig": 0.0},
    "humanoid": {"title": "The humanoid, E5.1 setting (flat, 5x5x5 maps, QARL; 100 trials)", "s_vig": -0.15},
}
OPTIMISERS = ("cma", "tpe", "safe_bo")
#: the defaults of an optimiser's settings (a group's label names the others)
DEFAULTS = {
    "gate": "off",
    "max_vetoes": 100,
    "failure_score": "flat",
    "sigma0": 0.25,
    "popsize": None,
    "restart_below": 0.0,
    "restart_from": "centre",
    "novel_draws": 64,
    "n_startup_trials": 10,
    "multivariate": False,
    "candidates": 1024,
    "min_success_probability": 0.5,
    "length_scale": 0.2,
    "refit_every": 10,
}
#: the target eta of "failures before a target eta": the lower quartile of the plain optimisers' best etas (three
#: quarters of their runs reach it), fixed before the runs were read
TARGET_QUANTILE = 0.25
ALPHA = 0.05


@dataclass
class Run:
    name: str
    path: Path
    walker: str
    label: str
    role: str  # sfl, random, plain, gated
    kind: str
    seed: int
    status: str
    reason: str
    rows: list
    wall_s: float | None
    s_vig: str = ""  # the vigilance its gate (or sfl) ran at, as labels write it: ``s_vig 0``
    metrics: dict | None = None


def vigilance_of(scenario: dict) -> str:
    """The vigilance a run's gate (or sfl) decides at, as the labels write it: ``s_vig 0``, ``adaptive s_vig from
    -0.15``."""
    vigilance = scenario["modules"]["vigilance"]["params"]
    mode = vigilance.get("mode", "fixed")
    value = float(vigilance.get("value", 0.0))
    if mode == "fixed":
        return f"s_vig {value:g}"
    if mode == "adaptive":
        return f"adaptive s_vig from {value:g}"
    return f"{mode} s_vig (4.14)"


def label_of(scenario: dict, walker: str) -> tuple[str, str, str]:
    """(label, role, kind) of a run's scenario: ``sfl, s_vig 0``, ``cma``, ``cma + gate (resample, ...)``."""
    proposer = scenario["protocol"].get("proposer") or {"kind": "sfl"}
    kind = proposer["kind"]
    vigilance = scenario["modules"]["vigilance"]["params"]
    mode = vigilance.get("mode", "fixed")
    value = float(vigilance.get("value", 0.0))
    s_vig = vigilance_of(scenario)
    if kind == "sfl":
        return f"sfl, {s_vig}", "sfl", kind
    if kind == "random":
        return "random", "random", kind
    gate = proposer.get("gate", "off")
    if gate is False:  # YAML's off
        gate = "off"
    settings = [f"{k} {v}" for k, v in proposer.items() if k not in ("kind", "gate") and DEFAULTS.get(k, v) != v]
    if mode != "fixed" or value != WALKERS[walker]["s_vig"]:
        settings.append(s_vig)
    if gate == "off":
        return kind + (f" ({', '.join(settings)})" if settings else ""), "plain", kind
    return f"{kind} + gate ({', '.join([gate, *settings])})", "gated", kind


def read_runs(runs: Path, layout: str = "{walker}") -> list[Run]:
    """Every learn run under ``runs/<folder>/<study>/`` for each walker (``layout``: ``{walker}``, or
    ``{walker}_explore`` for the dev seeds of what was tried)."""
    found = []
    for walker in WALKERS:
        for scenario_file in sorted((runs / layout.format(walker=walker)).glob("*/*/scenario.yaml")):
            folder = scenario_file.parent
            if folder.parent.name == "attempts" or folder.parent.parent.name == "attempts":
                continue
            scenario = yaml.safe_load(scenario_file.read_text())
            if scenario.get("protocol", {}).get("kind") != "learn":
                continue
            label, role, kind = label_of(scenario, walker)
            status, reason = run_status(folder)
            try:
                wall = json.loads((folder / "summary.json").read_text()).get("wall_time_s")
            except (OSError, ValueError):
                wall = None
            rows = read_records(folder)
            found.append(
                Run(
                    f"{folder.parent.name}/{folder.name}",
                    folder,
                    walker,
                    label,
                    role,
                    kind,
                    int(scenario["seed"]),
                    status,
                    reason,
                    rows,
                    wall,
                    vigilance_of(scenario),
                )
            )
    return found


def completed(runs: list[Run]) -> list[Run]:
    planned = {}
    for r in runs:
        planned[r.walker] = planned.get(r.walker, 0)
    return [r for r in runs if r.status == "completed" and r.metrics and r.metrics["trials"] > 0]


def group(runs: list[Run]) -> dict[str, list[Run]]:
    """Runs by label, in the page's order (sfl by vigilance, random, then each optimiser plain and gated), each group's
    runs by seed."""
    order = {"sfl": 0, "random": 1, "plain": 2, "gated": 2}
    groups: dict[str, list[Run]] = {}
    for r in sorted(
        runs,
        key=lambda r: (order[r.role], OPTIMISERS.index(r.kind) if r.kind in OPTIMISERS else 0, r.role, r.label, r.seed),
    ):
        groups.setdefault(r.label, []).append(r)
    return groups


def target_eta(runs: list[Run]) -> float | None:
    etas = [r.metrics["best_eta"] or 0.0 for r in runs if r.role == "plain" and r.kind in OPTIMISERS]
    return float(np.quantile(etas, TARGET_QUANTILE)) if etas else None


def decisions_per_trial(run: Run) -> float:
    return run.metrics["decisions_per_trial"] or 1.0


# --------------------------------------------------------------------------- the tables
def groups_table(groups: dict[str, list[Run]], target: float | None) -> list[str]:
    lines = [
        f"| group | seeds | failures | falls (`m_fell`) | failures before {K_GOOD} good gaits | failures before eta "
        f"{target:.3g} | distinct good gaits | best eta | tried where the gate says no-go | ACC evaluations "
        "per trial |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, runs in groups.items():
        m = [r.metrics for r in runs]
        per_trial = [decisions_per_trial(r) for r in runs]
        lines.append(
            f"| {label} | {len(runs)} | {bounded_cell([x['failures'] for x in m], '.1f')} "
            f"| {bounded_cell([x['falls'] for x in m], '.1f')} "
            f"| {censored_cell([x['failures_before_k'] if x['failures_before_k'] is not None else x['failures'] for x in m], [x['failures_before_k'] is None for x in m], '.3g')} "  # noqa: E501
            f"| {censored_cell([x['failures_before_target'] if x['failures_before_target'] is not None else x['failures'] for x in m], [x['failures_before_target'] is None for x in m], '.3g')} "  # noqa: E501
            f"| {bounded_cell([x['distinct_gaits'] for x in m], '.1f')} "
            f"| {bounded_cell([x['best_eta'] or 0.0 for x in m], '.3g')} "
            f"| {bounded_cell([x['no_go_trials'] for x in m], '.1f')} "
            f"| {np.mean(per_trial):.1f} ({min(per_trial):.1f}-{max(per_trial):.1f}) |"
        )
    return lines


def by_seed(runs: list[Run]) -> dict[int, dict]:
    return {r.seed: r.metrics for r in runs}


def paired(a: list[Run], b: list[Run], key) -> tuple[list[float], list[float]]:
    """The values of ``key`` in the seeds both groups have, in seed order."""
    sa, sb = by_seed(a), by_seed(b)
    seeds = sorted(set(sa) & set(sb))
    return [key(sa[s]) for s in seeds], [key(sb[s]) for s in seeds]


def failures(x: dict) -> float:
    return float(x["failures"])


def falls(x: dict) -> float:
    return float(x["falls"])


def best_eta(x: dict) -> float:
    return float(x["best_eta"] or 0.0)


def to_k(x: dict) -> tuple[float, bool]:
    return (
        (float(x["failures_before_k"]), False) if x["failures_before_k"] is not None else (float(x["failures"]), True)
    )


# --------------------------------------------------------------------------- the claims
def claims(walker: str, groups: dict[str, list[Run]]) -> list[Claim]:
    """The page's family of claims on one walker (fixed before the runs were read):

    - sfl (at the gate's vigilance) fails less than random search (the thesis's claim; seeds pair: the same draws);
    - for each optimiser and each of its gated groups: fewer failures than plain, fewer falls than plain, a best
      eta different from plain's (paired by seed: the same seed's runs start from the same population and maps);
      failures against sfl at the gate's vigilance (Welch); failures before 10 good gaits against sfl (a rank
      test, censored runs taken against the claim).
    """
    out: list[Claim] = []
    reference = f"sfl, s_vig {WALKERS[walker]['s_vig']:g}"
    sfl = groups.get(reference, [])
    if sfl and "random" in groups:
        a, b = paired(sfl, groups["random"], failures)
        if len(a) >= 2:
            t = stats.paired_log_t(a, b)
            out.append(
                Claim(f"{walker}: sfl-random", f"{walker}: {reference} fails {_less(t)} than random", t, "ratio")
            )
    for kind in OPTIMISERS:
        plain = groups.get(kind, [])
        for label, gated in groups.items():
            if not label.startswith(f"{kind} + gate"):
                continue
            if plain:
                for what, key in (("fails", failures), ("falls", falls)):
                    a, b = paired(gated, plain, key)
                    if len(a) >= 2:
                        t = stats.paired_log_t(a, b)
                        out.append(
                            Claim(
                                f"{walker}: {label} {what}",
                                f"{walker}: {label} {what} {_less(t)} than {kind}",
                                t,
                                "ratio",
                            )
                        )
                a, b = paired(gated, plain, best_eta)
                if len(a) >= 2 and min(a + b) > 0:
                    t = stats.paired_log_t(a, b, shift=0.0)
                    higher = "higher" if t.effect.estimate > 1 else "lower"
                    out.append(
                        Claim(
                            f"{walker}: {label} eta",
                            f"{walker}: {label}'s best eta is {higher} than {kind}'s",
                            t,
                            "ratio",
                        )
                    )
            if len(sfl) >= 2 and len(gated) >= 2:
                t = stats.welch_log_t([failures(r.metrics) for r in gated], [failures(r.metrics) for r in sfl])
                out.append(
                    Claim(
                        f"{walker}: {label} vs sfl", f"{walker}: {label} fails {_less(t)} than {reference}", t, "ratio"
                    )
                )
                g = [to_k(r.metrics) for r in gated]
                s = [to_k(r.metrics) for r in sfl]
                g_first = _median_to_k(g) <= _median_to_k(s)
                first, second = (g, s) if g_first else (s, g)
                t = stats.censored_rank_test(
                    [v for v, _ in first], [c for _, c in first], [v for v, _ in second], [c for _, c in second]
                )
                who, other = (label, reference) if g_first else (reference, label)
                out.append(
                    Claim(
                        f"{walker}: {label} to K vs sfl",
                        f"{walker}: {who} finds {K_GOOD} good gaits after fewer failures than {other}",
                        t,
                        "difference of medians",
                    )
                )
    return out


def _less(test: stats.Test) -> str:
    return "less" if test.effect.estimate < 1 else "more"


def _median_to_k(values: list[tuple[float, bool]]) -> float:
    m = stats.kaplan_meier_median([v for v, _ in values], [c for _, c in values])
    return np.inf if m is None else m


# --------------------------------------------------------------------------- the goals
def goals(walker: str, groups: dict[str, list[Run]]) -> list[str]:
    """The issue's goals, group by group: failures <= 0.5x plain and <= sfl's (means), best eta >= 0.98x plain in
    every seed; 10 good gaits in >= 4 of 5 seeds with failures before 10 <= sfl's."""
    reference = f"sfl, s_vig {WALKERS[walker]['s_vig']:g}"
    sfl = groups.get(reference, [])
    lines = [
        f"| gated group | failures / plain's (mean) | failures / {reference}'s (mean) | best eta / plain's, per seed "
        f"(min) | seeds reaching {K_GOOD} good gaits | failures before {K_GOOD}: mean over those seeds, "
        f"{reference}'s |",
        "|---|---|---|---|---|---|",
    ]
    sfl_f = np.mean([failures(r.metrics) for r in sfl]) if sfl else np.nan
    sfl_k = [r.metrics["failures_before_k"] for r in sfl if r.metrics["failures_before_k"] is not None]
    for kind in OPTIMISERS:
        plain = groups.get(kind, [])
        for label, gated in groups.items():
            if not label.startswith(f"{kind} + gate"):
                continue
            gf = np.mean([failures(r.metrics) for r in gated])
            pf = np.mean([failures(r.metrics) for r in plain]) if plain else np.nan
            a, b = paired(gated, plain, best_eta)
            ratios = [x / y for x, y in zip(a, b, strict=True) if y > 0]
            reached = [r.metrics["failures_before_k"] for r in gated if r.metrics["failures_before_k"] is not None]
            lines.append(
                f"| {label} | {gf / pf:.2f} {'(<= 0.5: met)' if gf <= 0.5 * pf else '(> 0.5: not met)'} "
                f"| {gf / sfl_f:.2f} {'(met)' if gf <= sfl_f else '(not met)'} "
                + (
                    f"| {' '.join(f'{x:.3f}' for x in ratios)} (min {min(ratios):.3f}: "
                    f"{'met' if min(ratios) >= 0.98 else 'not met'}) "
                    if ratios
                    else "| - "
                )
                + f"| {len(reached)} of {len(gated)} | "
                + (f"{np.mean(reached):.1f}; " if reached else "-; ")
                + (f"{np.mean(sfl_k):.1f} ({len(sfl_k)} of {len(sfl)} seeds)" if sfl_k else "-")
                + " |"
            )
    return lines


# --------------------------------------------------------------------------- the page
def run_metrics_of(run: Run) -> RunMetrics:
    success = np.array([bool(r["success"]) for r in run.rows if r.get("kind") == "trial"], dtype=bool)
    return RunMetrics(run.name, run.status, run.reason, run.metrics, success, run.wall_s)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, default=ROOT / "runs/baselines")
    parser.add_argument("--page", type=Path, default=ROOT / "docs/results/baselines.md")
    parser.add_argument("--figures", type=Path, default=ROOT / "docs/results/baselines")
    args = parser.parse_args()
    runs = read_runs(args.runs)
    explored = read_runs(args.runs, "{walker}_explore")
    for r in runs + explored:  # the target needs the plain runs' best eta first
        r.metrics = safe_learning(r.rows, K_GOOD, DISTINCT)
    targets = {}
    for walker in WALKERS:
        done = [r for r in runs if r.walker == walker and r.status == "completed" and r.metrics["trials"]]
        targets[walker] = target_eta(done)
        for r in runs + explored:
            if r.walker == walker:
                r.metrics = safe_learning(r.rows, K_GOOD, DISTINCT, targets[walker])
    args.figures.mkdir(parents=True, exist_ok=True)
    sections, all_claims, panels, goal_lines = {}, [], {}, {}
    settings = StudySettings()
    for walker in WALKERS:
        done = [r for r in runs if r.walker == walker and r.status == "completed" and r.metrics["trials"]]
        if not done or targets[walker] is None:
            continue
        groups = group(done)
        sections[walker] = groups
        all_claims += claims(walker, groups)
        goal_lines[walker] = goals(walker, groups)
        panels[walker] = {
            label: [(failures(r.metrics), best_eta(r.metrics)) for r in rs] for label, rs in groups.items()
        }
        out = args.figures / walker
        out.mkdir(exist_ok=True)
        shown = {label: [run_metrics_of(r) for r in rs] for label, rs in groups.items()}
        study_figures(shown, settings, out)
    tradeoff_figure({WALKERS[w]["title"].split(",")[0]: p for w, p in panels.items()}, args.figures / "tradeoff.png")
    claim_lines, adjusted = claims_table(all_claims, ALPHA)
    explore_groups = {
        w: group([r for r in explored if r.walker == w and r.status == "completed" and r.metrics["trials"]])
        for w in sections
    }
    left_out = [r for r in runs + explored if r.status != "completed" or not r.metrics["trials"]]
    numbers = {
        "targets": targets,
        "claims": {
            c.key: {
                "says": c.says,
                "test": c.test.name,
                "p": c.test.p,
                "holm_p": adjusted[c.key],
                "effect": [c.test.effect.estimate, c.test.effect.low, c.test.effect.high],
            }
            for c in all_claims
        },
        "runs": {
            f"{r.path.parent.parent.name}/{r.name}": {
                "label": r.label,
                "seed": r.seed,
                "status": r.status,
                **{k: v for k, v in r.metrics.items() if not isinstance(v, list)},
            }
            for r in runs + explored
        },
    }
    (args.figures / "numbers.json").write_text(json.dumps(numbers, indent=1, default=float) + "\n")
    said = summary(sections, {c.key: c for c in all_claims}, adjusted)
    args.page.write_text(page(sections, explore_groups, targets, claim_lines, goal_lines, said, left_out, args) + "\n")
    print(f"wrote {args.page} and {args.figures}/")


def seeds_of(groups: dict[str, list[Run]]) -> str:
    return ", ".join(f"{label}: {' '.join(str(r.seed) for r in rs)}" for label, rs in groups.items())


def summary(sections: dict, by_key: dict[str, Claim], adjusted: dict[str, float]) -> list[str]:
    """What the page says, group by group, each comparison with its verdict (computed: never a claim its test does
    not carry; the direction of each is the claims table's)."""

    def verdict(key: str) -> str:
        if key not in by_key:
            return "untested"
        holds = adjusted[key] < ALPHA
        return f"{'holds' if holds else 'not shown'}, Holm p = {adjusted[key]:.2g}"

    lines = ["## What this says", ""]
    for walker, groups in sections.items():
        reference = f"sfl, s_vig {WALKERS[walker]['s_vig']:g}"
        sfl = groups.get(reference, [])
        s_f = np.mean([failures(r.metrics) for r in sfl]) if sfl else np.nan
        s_k = sum(r.metrics["failures_before_k"] is not None for r in sfl)
        lines.append(f"On the {walker} walker:")
        lines.append("")
        plain_runs = [r for kind in OPTIMISERS for r in groups.get(kind, [])]
        if plain_runs:  # what a gate in front of them could spare at most: their failures where it says no-go
            m = [r.metrics for r in plain_runs]
            keys = ("failures", "no_go_trials", "no_go_failures")
            n_f, n_ng, n_ngf = (float(np.mean([x[k] for x in m])) for k in keys)
            kinds = ", ".join(k for k in OPTIMISERS if k in groups)
            lines.append(
                f"- What the gate could spare: the plain optimisers ({kinds}) "
                f"tried {n_ng:.1f} points a run where the gate says no-go, {n_ngf:.1f} of them failures, of their "
                f"{n_f:.1f} failures a run ({n_ngf / n_f:.0%}); their other failures were where it says go."
            )
        if sfl and "random" in groups:
            r_f = np.mean([failures(r.metrics) for r in groups["random"]])
            lines.append(
                f"- {reference} fails {s_f:.1f} times on average against random search's {r_f:.1f} "
                f"({verdict(f'{walker}: sfl-random')})."
            )
        for kind in OPTIMISERS:
            plain = groups.get(kind, [])
            for label, gated in groups.items():
                if not label.startswith(f"{kind} + gate") or not plain:
                    continue
                g_f, p_f = (np.mean([failures(r.metrics) for r in rs]) for rs in (gated, plain))
                g_l, p_l = (np.mean([falls(r.metrics) for r in rs]) for rs in (gated, plain))
                a, b = paired(gated, plain, best_eta)
                ratios = [x / y for x, y in zip(a, b, strict=True) if y > 0]
                g_k = sum(r.metrics["failures_before_k"] is not None for r in gated)
                text = (
                    f"- **{label}**: {g_f:.1f} failures against {kind}'s {p_f:.1f} ({g_f / p_f:.2f}x: "
                    f"{verdict(f'{walker}: {label} fails')}) and {reference}'s {s_f:.1f} "
                    f"({verdict(f'{walker}: {label} vs sfl')}); {g_l:.1f} falls against {p_l:.1f} "
                    f"({verdict(f'{walker}: {label} falls')}); best eta {np.mean(a):.3g} against {np.mean(b):.3g}, "
                    f"{min(ratios):.3f}-{max(ratios):.3f}x seed by seed (a difference: "
                    f"{verdict(f'{walker}: {label} eta')}); {K_GOOD} good gaits in {g_k} of {len(gated)} seeds, "
                    f"{reference} in {s_k} of {len(sfl)} (after fewer failures: "
                    f"{verdict(f'{walker}: {label} to K vs sfl')})."
                )
                lines.append(text)
        lines.append("")
    return lines


def explore_against_plain(explored: dict[str, list[Run]], final: dict[str, list[Run]]) -> str:
    """Each explored group's failures and best eta over its plain optimiser's run of the same seed, where that seed
    ran plain (in the final groups, or on a dev seed among the explored ones): the goals' yardsticks."""
    lines = []
    for what, key in (("Failures", failures), ("Best eta", best_eta)):
        parts = []
        for label, runs in explored.items():
            if label == runs[0].kind:  # a plain optimiser run on dev seeds: what the others are measured against
                continue
            plain = final.get(runs[0].kind, []) + explored.get(runs[0].kind, [])
            mine, theirs = paired(runs, plain, key)
            if mine:
                ratios = ", ".join(f"{a / b:.3f}" for a, b in zip(mine, theirs, strict=True) if b > 0)
                parts.append(f"{label} {ratios}")
        if parts:
            lines.append(f"{what} over the plain optimiser's run of the same seed: " + "; ".join(parts) + ".")
    parts = []
    for label, runs in explored.items():  # the goal's other yardstick: sfl at the vigilance the gate ran at
        sfl = [
            r
            for rs in [*final.values(), *explored.values()]
            for r in rs
            if r.role == "sfl" and r.s_vig == runs[0].s_vig
        ]
        mine, theirs = paired(runs, sfl, failures)
        if mine and runs[0].role == "gated":
            pairs = ", ".join(f"{a:g} / {b:g}" for a, b in zip(mine, theirs, strict=True))
            parts.append(f"{label} {pairs}")
    if parts:
        lines.append("Failures against sfl's at the same vigilance, seed by seed: " + "; ".join(parts) + ".")
    return "\n\n".join(lines)


def made_at(runs: list[Run]) -> str:
    """Which code made the runs, from each run's ``provenance.json`` (a ``+`` marks uncommitted changes)."""
    commits: dict[str, int] = {}
    for r in runs:
        try:
            made = json.loads((r.path / "provenance.json").read_text())
            commit = (made.get("commit") or "unknown")[:7] + ("+" if made.get("uncommitted_changes") else "")
        except (OSError, ValueError, AttributeError):
            commit = "unknown"
        commits[commit] = commits.get(commit, 0) + 1
    return (
        "Made at code commit "
        + ", ".join(f"`{c}` ({n} run{'s' if n != 1 else ''})" for c, n in sorted(commits.items(), key=lambda c: -c[1]))
        + "."
    )


def page(sections, explore_groups, targets, claim_lines, goal_lines, said, left_out, args) -> str:
    rel = args.figures.relative_to(args.page.parent)
    text = [HEADER]
    missing = [w for w in WALKERS if w not in sections]
    if missing:
        text += [
            "**Not on this page yet:** "
            + "; ".join(
                f"{WALKERS[w]['title']}: no completed run under `{w}/` "
                f"(`BODIES={w} bash docs/experiments/baselines.sh`)"
                for w in missing
            )
            + ". The claims and their Holm adjustment cover the walkers shown only.",
            "",
        ]
    for walker, groups in sections.items():
        text += [
            f"## {WALKERS[walker]['title']}",
            "",
            WALKER_TEXT.get(walker, ""),
            "",
            f"The target eta is {targets[walker]:.3g}: the lower quartile of the plain optimisers' best etas on this "
            "walker (three quarters of their runs reach it). Seeds per group: " + seeds_of(groups) + ".",
            "",
            made_at([r for rs in groups.values() for r in rs]),
            "",
            *groups_table(groups, targets[walker]),
            "",
            "The issue's goals, group by group (means over the seeds; best eta seed by seed, against the plain "
            "optimiser's run of the same seed). These are the goals' own yardsticks, not tests: the tests are below.",
            "",
            *goal_lines[walker],
            "",
            f"![]({rel}/{walker}/study_learning.png)",
            f"![]({rel}/{walker}/study_best_eta.png)",
            f"![]({rel}/{walker}/study_failures_before_k.png)",
            "",
        ]
    text += [
        "## Failures against best eta",
        "",
        f"![]({rel}/tradeoff.png)",
        "",
        "## The comparisons and their tests",
        "",
        CLAIMS_TEXT,
        "",
        *claim_lines,
        "",
    ]
    for walker, groups in explore_groups.items():
        if groups:
            text += [
                f"## What was tried to keep the gated optimisers exploring ({walker} walker, {EXPLORE_SEEDS[walker]})",
                "",
                EXPLORE_TEXT[walker],
                "",
                *groups_table(groups, targets[walker]),
                "",
                "Seeds: " + seeds_of(groups) + ". " + made_at([r for rs in groups.values() for r in rs]),
                "",
                explore_against_plain(groups, sections[walker]),
                "",
            ]
    if left_out:
        text += ["Left out of every number (did not complete):", ""]
        text += [f"- {r.walker}/{r.name}: {r.status}, {r.reason}" for r in left_out]
        text.append("")
    text += [*said, DISCUSSION]
    return "\n".join(text)


#: the page's text around the tables (kept here, so that the page is written whole by this script)
HEADER = """# Does the early warning make a good optimiser safe?

The thesis's contribution is the early warning: success and failure maps with a go/no-go decision (d_f - d_s >
s_vig, eq. 3.3). Success-failure learning (`sfl`) puts it in front of uniform random draws. The optimisers CMA-ES,
TPE and a safe Bayesian optimiser find good gaits sooner and better gaits than `sfl` (issue 22), but fail more. This
page asks whether the same early warning, put in front of those optimisers (`protocol.proposer.gate`,
[`docs/proposers.md`](../proposers.md)), makes them safe without costing them the gaits they find. Issue 33.

Made by `bash docs/experiments/baselines.sh`: one `sfl study` per group set on each walker, then
`docs/experiments/baselines_page.py` writes this page, its figures and `baselines/numbers.json` (every run's
metrics, every claim's test) from the run folders. Each walker's section says which code made its runs; wall times
depend on the machine and on what ran beside them, and are not shown.

**Groups.** `sfl` at a sweep of fixed vigilance (and, on the humanoid, adaptive vigilance from -0.15, §5.6.3);
CMA-ES, TPE and the safe optimiser (`safe_bo`) each plain (`gate: off`) and gated. A gated group runs at the walker's
own vigilance (planar 0, humanoid -0.15), the one its `sfl` reference group runs at; its label says the gate's mode
and any other setting that is not the default. One gated CMA-ES group's gate follows the thesis's vigilance schedule
instead (`scheduled s_vig (4.14)`, cautious first, adventurous later): chosen on the planar walker's dev seeds 10-12
(the explored groups below) and made a final group on 2026-11-29, before it ran on seeds 0-4; it is compared with the
same `sfl` reference. `random` (uniform draws, no gate) is shown where it was run.

**How to read the tables.** A *failure* is any unsuccessful trial: on the planar walker that is a fall or a stall
(standing after 10 s but under 0.5 m or 4 steps forward), on the humanoid a fall or leaving the lane before the
finish line. A *fall* is a trial whose body reports `fell` (`m_fell`). A *good gait* is a success at least 0.1 from
every good gait found before it (unit cube); "failures before 10 good gaits" counts the failures before the tenth.
"Failures before eta T" counts the failures before the first success whose eta reaches the walker's target T. Runs
that never got there are censored: the cell says how many runs reached it, with the mean when all did and the
Kaplan-Meier median otherwise (none when fewer than half did); a censored run is never averaged as if it had. Each
other value is the mean over the seeds with its 95 % percentile bootstrap interval (10 000 resamples): it stays within
the values' range (never below 0 for a count), but with five seeds it is narrower than a 95 % interval should be, so
it describes the spread; the tests below decide. "Tried where the gate says no-go" counts trials whose own decision
was a no-go: for a plain optimiser, every trial success-failure learning would have refused (its records now say it:
`go` is the gate's real decision for every proposer); for a gated one, trials tried after its veto budget was spent.

**The decision budget.** Every decision is one ACC evaluation (a request to the ACC process, 3-8 ms), free on the
body: only tried points are trials. The last column gives them per trial: `sfl` draws until the gate says go, so it
makes many per trial, and more the more cautious its vigilance; a plain optimiser makes one (the gate's decision is
recorded, not obeyed); a gated one makes one plus one per veto or redraw (at most `max_vetoes` = 100, then the point is
tried whatever the gate says), and CMA-ES with novel restarts 64 more per restart.

**The maps start at random weights.** Both maps are seeded with random weights in the unit cube, so the gate decides
from the very first draw: a first decision can be a no-go (the thesis's maps start the same way), and a run of `sfl`
and a run of `random` from the same seed part at the first draw the gate refuses.
"""
WALKER_TEXT: dict[str, str] = {}
CLAIMS_TEXT = """Every comparison this page makes is here, fixed in `baselines_page.py::claims` before the runs were
read: on each walker, `sfl` against random search (where random ran), and for each gated group against its plain
optimiser (failures, falls, best eta) and against `sfl` at the same vigilance (failures, failures before 10 good
gaits). Seeds pair between a gated group and its plain optimiser (the same seed starts both from the same population
or draws, the same maps and the same trial noise), so those are paired t-tests on the log scale: log(x + 1) for
counts, log eta for best eta; the effect is the ratio of geometric means, its interval from the log scale (always
positive). Against `sfl` the seeds do not pair (another proposer): Welch's t-test on log(x + 1). Failures before 10
good gaits has censored runs: a Mann-Whitney test with every censored run taken where it hurts the claim (see
`sfl_brain/report/stats.py`); with five seeds its p cannot go below 0.008. The p-values are two-sided, and Holm's
step-down adjustment runs over every claim of the page; a claim **holds** when its adjusted p is below 0.05. One that
does not is *not shown*, and the text does not make it."""
#: where each walker's explored groups ran, for the section's heading
EXPLORE_SEEDS = {"planar": "dev seeds", "humanoid": "the final seeds, at sfl's safest vigilance"}
EXPLORE_PLANAR = """Each was run on two seeds before the final groups were chosen: veto or resample on seeds 0 and 1,
which are also seeds of the final groups (their runs are the same, so the choice saw two of the five seeds), the
first restarts on seeds 10 and 11. Gated CMA-ES with `veto` tells every vetoed point to the strategy as a failure:
its mean moves away from the no-go region, and on the planar walker the most efficient gaits lie close to failures
(a plain CMA-ES run tries about half its points where the gate says no-go, table above), so it loses best eta (the
ratios below the table). With `resample` the strategy is told nothing of the gate and keeps its own path. TPE with
`resample` redraws from a model that learnt nothing of the refusal: on the analytic body and in the unit tests its
every redraw fell in the same no-go corner until the budget was spent (`tests/proposers/test_gate.py`), and it was
not run on the walkers; with `veto` the refused corner enters TPE's worse group. Restarts of CMA-ES from novel
gate-approved draws were tried at `restart_below` 0.05; the final group restarts when the step size falls below the
gaits' distinctness (0.1).

After the final groups (issue 33 item 2, 2026-11-28), on dev seeds 10, 11 and 12 only, each beside plain CMA-ES or
TPE run on the same seeds as its yardstick: the final restarts again; the restarts with a smaller step (`sigma0`
0.15, at the start and at every restart); and gated TPE drawing uniformly for its first 40 asks instead of 10
(`n_startup_trials` 40: a vetoed draw is told to TPE as a failure, so it counts among them), which puts the gate in
front of uniform draws, as `sfl` does, before TPE's model takes over. Their rows in the table and the ratios below
say how each did; none was made a final group.

Then (issue 33 item 2's third idea, 2026-11-28), on the same dev seeds 10-12: the gate's vigilance scheduled by the
thesis's (4.14) (`modules.vigilance.params.mode: scheduled`: s_vig drawn each trial in a band that falls from [0,
0.57] at the first trial to [-0.72, -0.15] at the 200th, cautious first, adventurous later) for gated CMA-ES and
gated TPE, beside the same gated optimisers at the fixed s_vig 0 of the final groups and `sfl` at s_vig 0, all on
those seeds (the last line below pairs each gated group at the fixed s_vig 0 with that `sfl` run; the scheduled ones
have no `sfl` run at their vigilance). And the issue's second idea, a failure scored by how far the trial got
(`failure_score: graded`, `progress - 1` in [-1, 0]) instead of a flat 0, behind the same gates on the same seeds.
Gated TPE asked exactly the points it asks with flat scores, decision for decision: TPE splits its trials into a
good and a bad group by score, and behind the gate (about nine successes in ten) its good group holds successes
only, so how failures rank among themselves does not reach its model. Gated CMA-ES with the scheduled vigilance was
then made a final group (2026-11-29, before it ran on seeds 0-4; its runs on seeds 0-4 are in the table above): of
the variants run on all three dev seeds, it alone kept its best eta at >= 0.98x its plain optimiser's in every seed
and reached 10 good gaits in all three, though it failed more often than plain CMA-ES there.

How far two runs of the same plain optimiser differ on this walker, which has no noise (ten seeds each of plain
CMA-ES and TPE, `baselines.sh`'s `planar/floor` set), is on [`baselines_floor.md`](baselines_floor.md): the bar of
the goals, best eta >= 0.98x in every one of five seeds, is met by a rerun of the plain optimiser itself in only
about a quarter of the pairings (24% CMA-ES, 30% TPE; an estimate from ten runs each)."""
EXPLORE_HUMANOID = """The humanoid's gated groups above decide at its scenario's vigilance, -0.15, a
risk-taking setting. Here the same gated CMA-ES (`resample`) and gated TPE (`veto`) decide at 0, the vigilance of
the safest `sfl` group, on the final seeds 0-4 (issue 33 item 2, 2026-11-28, `docs/experiments/baselines.sh`'s
`humanoid/explore` set). They are not final groups: the page's goals and claims are made on the groups above, and
these rows carry no test. The ratios below the table give each seed's failures and best eta over plain CMA-ES's or
TPE's run of the same seed (the goals ask <= 0.5 and >= 0.98 in every seed), and its failures beside `sfl`'s at
s_vig 0."""
EXPLORE_TEXT = {"planar": EXPLORE_PLANAR, "humanoid": EXPLORE_HUMANOID}
DISCUSSION = """"""

if __name__ == "__main__":
    main()
