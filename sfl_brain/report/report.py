"""``sfl report``: figures (PNG) and a Markdown table for finished runs.

* a sweep run: the viability map over the first two axes (success coloured by walking speed);
* a learn run: both maps after learning (from ``acc.npz``) over the tried points;
* for every run a table row: status first, then protocol, proposer (learn runs: what chose each trial's point,
  docs/proposers.md), vigilance, trials, success rate, next to the thesis's figure;
* learn runs whose scenarios differ by more than the seed (another proposer, any key) compared as a study's groups
  (:mod:`.study`), whether they come from ``sfl study`` or not;
* learn runs at two or more fixed vigilance values: success rate against s_vig, every seed a dot,
  the mean a line, the thesis's E3.2 values as crosses (Fig. 3.13), and a table of the means.

Runs whose controller is the CPG (chapter 4, E4.2) get the figures and tables of :mod:`.report_cpg` instead of
the generic map figure: the maps over (sigma_s, sigma_f) with each neuron's pattern, the energy order of the map
neurons (Fig. 4.16), the success rate over trials and a gait strip. When every run is one, the page is named
after the scenario (``e4_2_learn.md``) instead of ``README.md``.

Only ``completed`` runs enter a mean. A stalled, failed, interrupted or unfinished run keeps its row
(its status and stop reason shown) and is listed under the figure as left out.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402

from ..recording.provenance import describe_platform  # noqa: E402
from ..recording.records import read_records, run_status, summarise  # noqa: E402
from .ch5 import ch5_sections, is_ch5_run  # noqa: E402
from .conditions import conditions_section, is_conditions_run  # noqa: E402
from .cpg import cpg_run, is_cpg_run, write_cpg_sections  # noqa: E402
from .study import StudySettings, study_section  # noqa: E402
from .sweep import is_grid_sweep, sweep_section  # noqa: E402
from .terrain import terrain_sections  # noqa: E402


def proposer_of(scenario: dict) -> str:
    """What chose a learn run's points, as a page names it: the proposer's kind (``sfl`` when the scenario names
    none, the default) and its gate when it has one (``cma, gate veto``); ``-`` for other protocols."""
    if scenario.get("protocol", {}).get("kind") != "learn":
        return "-"
    proposer = scenario["protocol"].get("proposer") or {}
    gate = proposer.get("gate", "off")
    return proposer.get("kind", "sfl") + (f", gate {gate}" if gate != "off" else "")


def _figure(run_dir: Path, out: Path, scenario: dict, rows: list[dict]) -> str:
    trials = [r for r in rows if r["kind"] == "trial" and r.get("v_unit")]
    if not trials:
        return ""
    names = [a["name"] for a in scenario["space"]]
    unit = np.array([r["v_unit"][:2] for r in trials])
    ok = np.array([bool(r["success"]) for r in trials])
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    if scenario["protocol"]["kind"] == "sweep":
        speed = np.array([r.get("m_velocity") or 0.0 for r in trials])
        ax.scatter(unit[~ok, 0], unit[~ok, 1], s=6, c="lightgrey", label="failure")
        sc = ax.scatter(unit[ok, 0], unit[ok, 1], s=8, c=speed[ok], cmap="viridis", label="walks")
        fig.colorbar(sc, label="walking speed, m/s")
        ax.set_title(f"viability: {ok.mean():.0%} of {len(ok)} walk")
    else:
        ax.scatter(unit[ok, 0], unit[ok, 1], s=5, c="#8fd19e", label="success trials")
        ax.scatter(unit[~ok, 0], unit[~ok, 1], s=5, c="#f2a0a0", label="failure trials")
        maps = run_dir / "acc.npz"
        if maps.exists():
            with np.load(maps) as data:
                for name, colour in (("success", "green"), ("failure", "red")):
                    w = data[f"{name}_weights"][:, :2]
                    active = data[f"{name}_active"]
                    ax.scatter(w[active, 0], w[active, 1], s=25, c=colour, edgecolors="k", label=f"{name} map")
        ax.set_title(f"{scenario['name']} ({proposer_of(scenario)}): {ok.mean():.0%} success in {len(ok)} trials")
    ax.set_xlabel(f"{names[0]} (unit)")
    ax.set_ylabel(f"{names[1]} (unit)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend(fontsize=7, loc="upper right")
    path = out / f"{run_dir.name}.png"
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path.name


#: the thesis's success rates by experiment (scenario names start with the experiment id)
THESIS_RATES = {
    "e3_2": {0.05: 0.98, 0.0: 0.96, -0.1: 0.45, -0.2: 0.28},  # §3.5.1, flat ground, 10x10 maps
    "e3_4": {0.0: 0.86, -0.2: 0.15},  # §3.5.2, slopes, 5x5x5 maps
}


def _thesis(name: str) -> dict[float, float]:
    return next((rates for prefix, rates in THESIS_RATES.items() if name.startswith(prefix)), {})


def _vigilance_figure(points: list[tuple[float, float, int]], out: Path, group: str, thesis: dict) -> list[str]:
    """Success rate against fixed s_vig over the runs (seeds) of one parameter space; table lines."""
    values = sorted({v for v, _, _ in points})
    if len(values) < 2:
        return []
    png = f"success_vs_vigilance_{group}.png"
    axes = group.replace("-", ", ")
    fig, ax = plt.subplots(figsize=(5.5, 4))
    xs = np.array([v for v, _, _ in points])
    ys = np.array([r for _, r, _ in points])
    none = np.isnan(ys)  # runs in which no candidate passed the early warning: no trial at all
    ax.scatter(xs[~none], ys[~none], s=14, c="tab:blue", alpha=0.6, label="one run (seed)")
    if none.any():
        ax.scatter(xs[none], np.zeros(none.sum()), s=30, marker="v", c="grey", label="run with no trial (all no-go)")
    means = [float(np.nanmean(ys[xs == v])) if (~np.isnan(ys[xs == v])).any() else float("nan") for v in values]
    ax.plot(values, means, "-o", c="tab:blue", label="mean over seeds (runs with trials)")
    if thesis:
        tv = sorted(thesis)
        ax.plot(tv, [thesis[v] for v in tv], "kx", ms=8, label="thesis")
    ax.set_xlabel("vigilance threshold s_vig")
    ax.set_ylabel("rate of succeeded trials")
    ax.set_ylim(0, 1.02)
    ax.invert_xaxis()
    ax.legend(fontsize=7)
    ax.set_title(f"success rate against vigilance over ({axes})", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / png, dpi=110)
    plt.close(fig)
    lines = [
        "",
        f"## Success rate against vigilance over ({axes})",
        "",
        f"![]({png})",
        "",
        "| s_vig | runs | trials (mean) | success rate, mean | min | max | thesis |",
        "|---|---|---|---|---|---|---|",
    ]
    for v, mean in zip(values, means, strict=True):
        rates = ys[xs == v]
        trials = np.mean([n for x, _, n in points if x == v])
        ref = f"{thesis[v]:.0%}" if v in thesis else ""
        if np.isnan(rates).all():
            lines.append(f"| {v:+.2f} | {len(rates)} | 0 | no trial | - | - | {ref} |")
            continue
        lines.append(
            f"| {v:+.2f} | {len(rates)} | {trials:.0f} | {mean:.1%} | {np.nanmin(rates):.1%} | {np.nanmax(rates):.1%} "
            f"| {ref} |"
        )
    return lines


def made_by(run_dirs: list[Path]) -> str:
    """One line saying what made the runs: the source commits (and whether any had uncommitted changes), the days
    they started and the numeric platforms they ran on, from each run folder's ``provenance.json`` (its file time for
    runs made before ``started``). Re-running a page's command at its commit gives its numbers exactly on the same
    numeric platform (the CPU's SIMD kernels that numpy and OpenBLAS use decide the last bits of a float, which a
    walk amplifies: docs/records.md, "Reproducibility")."""
    commits, days, platforms, dirty, unknown = [], [], [], False, 0
    for run_dir in run_dirs:
        path = run_dir / "provenance.json"
        try:
            made = json.loads(path.read_text())
        except (OSError, ValueError):
            unknown += 1
            continue
        commit = (made.get("commit") or "")[:7] or "no git commit"
        commits += [commit] if commit not in commits else []
        dirty |= bool(made.get("uncommitted_changes"))
        started = made.get("started") or datetime.fromtimestamp(path.stat().st_mtime, UTC).isoformat()
        days += [started[:10]] if started[:10] not in days else []
        platform = describe_platform(made.get("numeric_platform"))
        platforms += [platform] if platform not in platforms else []
    text = (
        f"Runs made at {', '.join(f'`{c}`' for c in commits) or 'an unknown commit'}"
        f"{' (some with uncommitted changes)' if dirty else ''}, started {', '.join(sorted(days)) or 'on unknown days'}"
        f", on {'; '.join(platforms) or 'an unknown numeric platform'}"
    )
    return text + (f"; {unknown} runs have no provenance.json." if unknown else ".")


def write_report(run_dirs: list[Path], out: Path, study: StudySettings | None = None) -> Path:
    """Write the page, its figures and ``summary.json`` for ``run_dirs`` into ``out``; with ``study``, the runs are a
    study's, and the page starts with its groups compared (:mod:`.report_study`, numbers in ``study_summary.json``)."""
    out.mkdir(parents=True, exist_ok=True)
    groups: dict[str, list[tuple[float, float, int]]] = {}
    group_thesis: dict[str, dict] = {}
    left_out: dict[str, list[str]] = {}
    statuses: dict[str, dict] = {}
    cpg_results: list[dict] = []
    conditions: dict[str, tuple[dict, list[Path], list[str]]] = {}  # scenario name -> (scenario, completed, left out)
    sweep_lines: list[str] = []
    sweep_names: set[str] = set()  # grid sweeps shown by report_sweep
    ch5_runs: list[Path] = []  # chapter 5's learn runs (report_ch5)
    ch5_names: set[str] = set()
    summaries: dict[str, dict] = {}
    lines = [
        "| run | status | protocol | proposer | s_vig | trials | success rate | thesis | figure |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for run_dir in run_dirs:
        scenario = yaml.safe_load((run_dir / "scenario.yaml").read_text())
        rows = read_records(run_dir)
        summary = summaries[str(run_dir)] = summarise(rows)
        status, why = run_status(run_dir)
        statuses[str(run_dir)] = {"status": status, "stop_reason": why}
        completed = status == "completed"
        vig = scenario.get("modules", {}).get("vigilance", {}).get("params", {})
        s_vig = vig.get("value") if vig.get("mode", "fixed") == "fixed" else vig.get("mode")
        learn = scenario["protocol"]["kind"] == "learn"
        rates = _thesis(scenario["name"]) if learn else {}
        thesis = f"{rates[s_vig]:.0%}" if isinstance(s_vig, int | float) and s_vig in rates else ""
        if is_ch5_run(scenario):
            ch5_runs.append(run_dir)
            ch5_names.add(scenario["name"])
            figure = ""
        elif is_conditions_run(scenario):
            entry = conditions.setdefault(scenario["name"], (scenario, [], []))
            if completed:
                entry[1].append(run_dir)
            else:
                entry[2].append(f"{run_dir.name}: {status}, {why}")
            figure = ""
        elif is_grid_sweep(scenario) and scenario["modules"].get("controller", {}).get("impl") == "cpg":
            sweep_lines += sweep_section(run_dir, out, scenario, rows)
            sweep_names.add(scenario["name"])
            figure = ""
        elif is_cpg_run(scenario):
            cpg_results.append(cpg_run(run_dir, out, scenario, status))
            figure = next(iter(cpg_results[-1]["figures"]), "")
        else:
            figure = _figure(run_dir, out, scenario, rows)
        rate = summary["success_rate"]
        if learn and isinstance(s_vig, int | float):
            group = "-".join(a["name"] for a in scenario["space"])
            if completed:
                groups.setdefault(group, []).append(
                    (float(s_vig), float("nan") if rate is None else float(rate), int(summary["trials"]))
                )
            else:
                left_out.setdefault(group, []).append(f"{run_dir.name} (s_vig {s_vig}): {status}, {why}")
            group_thesis[group] = rates if group_thesis.get(group, rates) == rates else {}
        shown_status = status if completed else f"**{status}**"
        lines.append(
            f"| {run_dir.name} | {shown_status} | {scenario['protocol']['kind']} | {proposer_of(scenario)} | "
            f"{s_vig if s_vig is not None else '-'} | "
            f"{summary['trials']} | {'-' if rate is None else f'{rate:.1%}'} | {thesis} | "
            f"{f'![]({figure})' if figure else ''} |"
        )
    vigilance_lines = []
    for group in {**groups, **left_out}:
        vigilance_lines += _vigilance_figure(groups.get(group, []), out, group, group_thesis[group])
        if left_out.get(group):
            vigilance_lines += [
                "",
                f"Left out of the means above: {len(left_out[group])} runs that did not complete:",
                "",
            ]
            vigilance_lines += [f"- {text}" for text in left_out[group]]
    unfinished = [d for d, st in statuses.items() if st["status"] != "completed"]
    vigilance_lines += write_cpg_sections(cpg_results) if cpg_results else []
    vigilance_lines += [""] + sweep_lines if sweep_lines else []
    vigilance_lines += [""] + ch5_sections(ch5_runs, out) if ch5_runs else []
    for scenario, completed_runs, skipped in conditions.values():
        vigilance_lines += [""] + conditions_section(scenario, completed_runs, skipped, out)
        vigilance_lines += terrain_sections(scenario, completed_runs)
    names = sorted({r["scenario"] for r in cpg_results})
    stem = names[0] if len(cpg_results) == len(run_dirs) and len(names) == 1 else None
    if len(conditions) == 1 and sum(len(c[1]) + len(c[2]) for c in conditions.values()) == len(run_dirs):
        stem = next(iter(conditions))
    if len(ch5_names) == 1 and len(ch5_runs) == len(run_dirs):
        stem = next(iter(ch5_names))  # chapter 5's learn runs: one page (e5_learn.md)
    if len(sweep_names) == 1 and len(run_dirs) == 1 and not conditions and not cpg_results:
        stem = next(iter(sweep_names))  # one grid sweep: its page is named after it (e4_2_grid.md)
    head = f"# Results of {stem} (`sfl report`)\n\n" if stem else "# Results\n\n"
    if unfinished:
        head += (
            f"{len(unfinished)} of {len(run_dirs)} runs did not complete (status in bold); "
            "they are shown but enter no mean.\n\n"
        )
    head += made_by(run_dirs) + "\n\n"
    if study is not None:
        study_lines, numbers = study_section(run_dirs, out, study)
        if study_lines:
            head += "\n".join(study_lines) + "\n\n## Runs\n\n"
            (out / "study_summary.json").write_text(json.dumps(numbers, indent=1) + "\n")
    path = out / (f"{stem}.md" if stem else "README.md")
    path.write_text(head + "\n".join(lines + vigilance_lines) + "\n")
    (out / (f"{stem}_summary.json" if stem else "summary.json")).write_text(
        json.dumps({str(d): {**statuses[str(d)], **summaries[str(d)]} for d in run_dirs}, indent=1)
    )
    return path
