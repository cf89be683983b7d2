"""``sfl report`` for a study: its runs grouped by what was varied, compared on the safe-learning metrics.

A group is every run whose scenario is the same except for its seed (the keys that differ between the runs'
``scenario.yaml`` name the groups, ``value=0.1`` or ``kind=random``: whatever ``--vary`` changed, or whatever differs
between the runs given to ``sfl report``: :func:`differ`). For each group, over its completed runs (seeds):

- learning curves against trials: the success rate over a moving window of trials and the cumulative failures,
  the mean over seeds with a 95 % bootstrap band (:func:`.stats.bootstrap_band`: within the seeds' range, so a band
  of two seeds is their envelope, not the whole plot), light fills with dashed edges drawn above every fill so that
  no band hides another; the best eta so far the same way;
- failures before K distinct good gaits (:func:`sfl_brain.recording.metrics.safe_learning`) as box plots, with the runs
  that never got there (censored) drawn apart at their total failures, a lower bound, keyed in black in a box below
  the axes (no group's colour, not among the data);
- a table: seeds, failures before the first success, failures before K, failures, falls, the success rate over the
  last window, the best eta and the wall time, each as the mean and its 95 % percentile bootstrap interval over the
  seeds (:func:`.stats.bootstrap_mean`: within the values' range, never below 0 for a count), with censored
  counts; at :data:`.stats.FEW` seeds or fewer the seeds' values instead of an interval that would be their range.

For pages that compare groups and make claims (``docs/results/baselines.md``): :func:`bounded_cell`,
:func:`censored_cell`, :func:`tradeoff_figure` (failures against best eta per group) and :class:`Claim` with
:func:`claims_table` (each claim's test, effect, p and Holm-adjusted p over the page's family; a claim whose adjusted
p is not below alpha is marked not shown).

A run that did not complete (stalled, failed, interrupted, killed) is in no curve, box or mean: it is named under
the table with its status and why.
"""

from __future__ import annotations

import json
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from ..recording.metrics import DISTINCT, K_GOOD, safe_learning, trial_rows  # noqa: E402
from ..recording.records import read_records, run_status  # noqa: E402
from ..study.study import WINDOW  # noqa: E402
from .stats import FEW, Test, bootstrap_band, bootstrap_mean, holm, kaplan_meier_median  # noqa: E402

#: figure width (in) and font size (pt): readable on a printed page
WIDTH_IN = 6.5
FONT_PT = 9
STYLE = {
    "font.size": FONT_PT,
    "axes.titlesize": FONT_PT + 1,
    "axes.labelsize": FONT_PT,
    "xtick.labelsize": FONT_PT,
    "ytick.labelsize": FONT_PT,
    "legend.fontsize": FONT_PT,
}
ETA_LABEL = "best eta so far (dimensionless)"


@dataclass(frozen=True)
class StudySettings:
    """What the study report measures: K distinct good gaits, ``distinct`` apart in the unit cube, and the window
    (trials) of the success rate."""

    k: int = K_GOOD
    distinct: float = DISTINCT
    window: int = WINDOW
    #: how the study saw the runs that did not complete (``status: reason``), those without a run folder too (e.g. a
    #: Dask task whose workers died)
    said: dict[str, str] = field(default_factory=dict)


# --------------------------------------------------------------------------- statistics
def interval_numbers(values) -> dict:
    """The finite ``values``' mean and its 95 % percentile bootstrap interval (:func:`.stats.bootstrap_mean`: within
    the values' range, so within the possible one) with n, for ``study_summary.json``; ``interval`` says what
    ``low`` and ``high`` are: ``bootstrap 95 %``, ``range`` (n <= FEW: the bootstrap interval is the values' range) or
    ``none`` (n < 2)."""
    a = [float(v) for v in values if v is not None and np.isfinite(v)]
    interval = bootstrap_mean(a)
    kind = "none" if len(a) < 2 else "range" if len(a) <= FEW else "bootstrap 95 %"
    low, high = (None, None) if len(a) < 2 else (interval.low, interval.high)
    return {"mean": interval.estimate if a else None, "low": low, "high": high, "n": len(a), "interval": kind}


def moving_success_rate(success, window: int) -> np.ndarray:
    """The success rate over the last ``window`` trials, after each trial (over the trials so far before that)."""
    s = np.asarray(success, dtype=float)
    total = np.cumsum(s)
    before = np.concatenate([np.zeros(min(window, len(s))), total[:-window]]) if len(s) else s
    return (total - before) / np.minimum(np.arange(1, len(s) + 1), window)


# --------------------------------------------------------------------------- groups
def flatten(value, prefix: str = "") -> dict[str, object]:
    """A scenario as ``key.path -> value`` (list items by index)."""
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list):
        items = enumerate(value)
    else:
        return {prefix: value}
    out: dict[str, object] = {}
    for key, item in items:
        out.update(flatten(item, f"{prefix}.{key}" if prefix else str(key)))
    if not out:
        out[prefix] = value
    return out


_MISSING = object()


def varied_keys(scenarios: list[dict]) -> list[str]:
    """The key paths whose value is not the same in every scenario, the seed apart (in the order of the first)."""
    flat = [flatten(s) for s in scenarios]
    keys: list[str] = []
    for f in flat:
        keys += [k for k in f if k not in keys]
    varied = []
    for key in keys:
        if key == "seed":
            continue
        values = [json.dumps(f.get(key, _MISSING), default=str, sort_keys=True) if key in f else None for f in flat]
        if len(set(values)) > 1:
            varied.append(key)
    return varied


def short_names(keys: list[str]) -> dict[str, str]:
    """Each key by its shortest dotted tail that no other key ends with (``modules.vigilance.params.value`` ->
    ``value``)."""
    names = {}
    for key in keys:
        parts = key.split(".")
        for n in range(1, len(parts) + 1):
            tail = ".".join(parts[-n:])
            if not any(other != key and (other == tail or other.endswith("." + tail)) for other in keys):
                break
        names[key] = tail
    return names


def group_label(scenario: dict, keys: list[str], names: dict[str, str]) -> str:
    flat = flatten(scenario)
    return ", ".join(f"{names[k]}={_show(flat.get(k, '(none)'))}" for k in keys) or "all runs"


def _show(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def group_runs(scenarios: dict[str, dict]) -> dict[str, list[str]]:
    """Run names by group label (every run whose scenario is the same but for the seed), in the runs' order."""
    keys = varied_keys(list(scenarios.values()))
    names = short_names(keys)
    groups: dict[str, list[str]] = {}
    for run, scenario in scenarios.items():
        groups.setdefault(group_label(scenario, keys, names), []).append(run)
    return groups


# --------------------------------------------------------------------------- one run
@dataclass
class RunMetrics:
    name: str
    status: str
    reason: str
    metrics: dict
    success: np.ndarray
    wall_s: float | None


def run_metrics(run_dir: Path, settings: StudySettings) -> RunMetrics:
    rows = read_records(run_dir)
    status, reason = run_status(run_dir)
    try:
        wall = json.loads((run_dir / "summary.json").read_text()).get("wall_time_s")
    except (OSError, ValueError, AttributeError):
        wall = None
    success = np.array([bool(r["success"]) for r in trial_rows(rows)], dtype=bool)
    # safe_learning cannot take a run without a trial (it reshapes an empty array); such a run is left out anyway
    metrics = safe_learning(rows, settings.k, settings.distinct) if len(success) else {}
    return RunMetrics(run_dir.name, status, reason, metrics, success, wall)


# --------------------------------------------------------------------------- figures
#: a band's fill: light enough that a band drawn later does not hide one drawn before (its dashed edges, drawn above
#: every fill, show where each band ends)
BAND_ALPHA = 0.15
BAND_TITLE = f"band: 95 % bootstrap interval, dashed edges (at {FEW} seeds or fewer, their range)"


def _colours(n: int) -> list:
    """A colour per group: tab10's; past 10 groups, tab20's dark ten and then its light ten (no two alike)."""
    if n <= 10:
        return [plt.get_cmap("tab10")(i) for i in range(n)]
    tab20 = plt.get_cmap("tab20")
    return [tab20((2 * i) % 20 + (2 * i) // 20) for i in range(n)]


def _legend_columns(labels: list[str]) -> int:
    """Legend columns that fit the page's width: three short labels a row, two longer ones, one long one."""
    longest = max((len(label) for label in labels), default=0)
    return min(len(labels), 3 if longest <= 32 else 2 if longest <= 50 else 1) or 1


def _mean_and_band(ax, curves: list, colour, label: str) -> None:
    """One group's mean curve over its seeds and its bootstrap band (:func:`.stats.bootstrap_band`: within the seeds'
    range): a light fill under every line, its edges dashed above every fill, the mean above them."""
    mean, low, high = bootstrap_band(curves)
    x = np.arange(1, len(mean) + 1)
    ax.fill_between(x, low, high, color=colour, alpha=BAND_ALPHA, lw=0, zorder=1)
    for edge in (low, high):
        ax.plot(x, edge, color=colour, lw=0.7, ls="--", zorder=3)
    ax.plot(x, mean, color=colour, lw=1.6, zorder=4, label=label)


def curves_figure(groups: dict[str, list[RunMetrics]], settings: StudySettings) -> plt.Figure:
    """Success rate over the moving window and cumulative failures against trials, mean and band per group."""
    fig, (rate_ax, fail_ax) = plt.subplots(1, 2, figsize=(WIDTH_IN, 2.9))
    for colour, (label, runs) in zip(_colours(len(groups)), groups.items(), strict=True):
        shown = f"{label} (n={len(runs)})"
        _mean_and_band(rate_ax, [moving_success_rate(r.success, settings.window) for r in runs], colour, shown)
        failures = [np.asarray(r.metrics["cumulative_failures"], dtype=float) for r in runs]
        _mean_and_band(fail_ax, failures, colour, shown)
    rate_ax.set_xlabel("trial (count)")
    rate_ax.set_ylabel(f"success rate, last {settings.window} trials\n(fraction of trials)")
    rate_ax.set_ylim(-0.02, 1.02)
    fail_ax.set_xlabel("trial (count)")
    fail_ax.set_ylabel("cumulative failures (trials)")
    fail_ax.set_ylim(bottom=0)
    handles, labels = rate_ax.get_legend_handles_labels()
    ncol = _legend_columns(labels)
    rows = -(-len(labels) // ncol)
    height = 2.9 + 0.18 * rows  # the axes keep their height; the legend's rows below them
    fig.set_size_inches(WIDTH_IN, height)
    fig.legend(handles, labels, loc="lower center", ncol=ncol, frameon=False)
    fig.suptitle(f"Learning curves: mean over seeds;\n{BAND_TITLE}", fontsize=FONT_PT + 1)
    fig.tight_layout(rect=(0, (0.18 * rows + 0.1) / height, 1, 1))
    return fig


def eta_figure(groups: dict[str, list[RunMetrics]]) -> plt.Figure:
    """The best eta so far against trials (0 before a run's first success), mean and band per group."""
    fig, ax = plt.subplots(figsize=(WIDTH_IN, 2.8))
    for colour, (label, runs) in zip(_colours(len(groups)), groups.items(), strict=True):
        # 0 before a run's first success: no gait yet (a failed trial's eta is 0)
        curves = [np.array([0.0 if v is None else v for v in r.metrics["best_eta_so_far"]]) for r in runs]
        _mean_and_band(ax, curves, colour, f"{label} (n={len(runs)})")
    ax.set_xlabel("trial (count)")
    ax.set_ylabel(ETA_LABEL)
    ax.set_ylim(bottom=0)
    ax.set_title(f"Best eta so far (0 before a first success): mean over seeds;\n{BAND_TITLE}")
    ax.legend(loc="lower right", frameon=False)
    fig.tight_layout()
    return fig


#: the key to the censored marker: black, a colour no group has, in a framed box below the axes, so it cannot be
#: read as a run
CENSORED_KEY = {"marker": "^", "color": "black", "markerfacecolor": "none", "markersize": 7, "linestyle": "none"}


def failures_figure(groups: dict[str, list[RunMetrics]], settings: StudySettings) -> plt.Figure:
    """Failures before K distinct good gaits per group: a box over the runs that got there, the censored runs (never
    got there) as open triangles at their total failures (a lower bound), keyed below the axes."""
    fig, ax = plt.subplots(figsize=(WIDTH_IN, 3.3))
    rng = np.random.default_rng(0)  # a fixed jitter of the dots
    any_censored = False
    for i, (colour, runs) in enumerate(zip(_colours(len(groups)), groups.values(), strict=True), 1):
        reached = [r.metrics["failures_before_k"] for r in runs if r.metrics["failures_before_k"] is not None]
        censored = [r.metrics["failures"] for r in runs if r.metrics["failures_before_k"] is None]
        if reached:
            ax.boxplot([reached], positions=[i], widths=0.5, showfliers=False, medianprops={"color": colour})
            ax.scatter(i + rng.uniform(-0.12, 0.12, len(reached)), reached, s=14, color=colour, zorder=3)
        if censored:
            jitter = i + rng.uniform(-0.12, 0.12, len(censored))
            ax.scatter(jitter, censored, s=36, marker="^", facecolors="none", edgecolors=colour, zorder=3)
            any_censored = True
    ax.set_xticks(range(1, len(groups) + 1))
    crowded = len(groups) > 4 or max(len(label) for label in groups) > 24  # slanted, wrapped labels
    ax.set_xticklabels(
        [
            f"{textwrap.fill(label, 24) if crowded else label}\n"
            f"{sum(r.metrics['failures_before_k'] is None for r in runs)} censored of {len(runs)}"
            for label, runs in groups.items()
        ],
        rotation=35 if crowded else 0,
        ha="right" if crowded else "center",
        fontsize=FONT_PT - 1 if crowded else None,
    )
    if crowded:
        fig.set_size_inches(WIDTH_IN, 3.3 + 1.4)
    ax.set_xlim(0.4, len(groups) + 0.6)
    ax.set_ylim(bottom=0)
    ax.set_ylabel(f"failures before K={settings.k}\ndistinct good gaits (trials)")
    ax.set_title(f"Failures before {settings.k} good gaits at least {settings.distinct:g} apart (unit cube)")
    bottom = 0.0
    if any_censored:
        key = Line2D([], [], **CENSORED_KEY)
        text = f"key: a censored run, fewer than K={settings.k} good gaits (drawn at its total failures, a lower bound)"
        fig.legend([key], [text], loc="lower center", frameon=True, fontsize=FONT_PT - 1)
        bottom = 0.1
    fig.tight_layout(rect=(0, bottom, 1, 1))
    return fig


def _figure_file(build, out: Path, name: str) -> str:
    """Build a figure in the page's style (``build()``), write it to ``out / name`` and return ``name``."""
    with plt.rc_context(STYLE):
        fig = build()
        fig.savefig(out / name, dpi=150)
    plt.close(fig)
    return name


def study_figures(groups: dict[str, list[RunMetrics]], settings: StudySettings, out: Path) -> list[str]:
    """The study's three figures of ``groups`` written to ``out``: learning curves, best eta, failures before K;
    their file names."""
    return [
        _figure_file(lambda: curves_figure(groups, settings), out, "study_learning.png"),
        _figure_file(lambda: eta_figure(groups), out, "study_best_eta.png"),
        _figure_file(lambda: failures_figure(groups, settings), out, "study_failures_before_k.png"),
    ]


# --------------------------------------------------------------------------- the page
def bounded_cell(values, digits: str = ".3g") -> str:
    """The mean of the finite ``values`` and its 95 % percentile bootstrap interval, ``mean [low, high]`` (``-``
    without a value). With :data:`.stats.FEW` values or fewer that interval would be only their range, not 95 %:
    the values are listed instead, ``mean (n=2: a, b)``; one value is ``value (n=1)``."""
    a = [float(v) for v in values if v is not None and np.isfinite(v)]
    if not a:
        return "-"
    interval = bootstrap_mean(a)
    if len(a) == 1:
        return f"{a[0]:{digits}} (n=1)"
    if len(a) <= FEW:
        return f"{interval.estimate:{digits}} (n={len(a)}: {', '.join(f'{v:{digits}}' for v in sorted(a))})"
    return f"{interval.estimate:{digits}} [{interval.low:{digits}}, {interval.high:{digits}}]"


def censored_cell(values, censored, digits: str = ".3g") -> str:
    """Counts to an event some runs never reached (``censored``; their value a lower bound): how many reached it, and
    the mean with its bootstrap interval when all did, else the Kaplan-Meier median (none when under half
    did)."""
    values, censored = list(values), [bool(c) for c in censored]
    n, reached = len(values), censored.count(False)
    if n == 0:
        return "-"
    if reached == n:
        return f"{bounded_cell(values, digits)} (all {n})"
    median = kaplan_meier_median(values, censored)
    shown = "no median (under half reach it)" if median is None else f"median {median:{digits}} (Kaplan-Meier)"
    return f"{reached} of {n} reach it; {shown}"


def _cell(values, censored: list | None = None, digits: str = ".3g") -> str:
    text = bounded_cell(values, digits)
    if censored:
        text += f" ({len(censored)} censored, at ≥ {', '.join(f'{c:g}' for c in sorted(censored))})"
    return text


def group_table(groups: dict[str, list[RunMetrics]], settings: StudySettings) -> list[str]:
    """The Markdown table of the groups: the mean and its 95 % bootstrap interval over each group's completed runs."""
    lines = [
        f"| group | seeds | failures before first success | failures before K={settings.k} | failures, all trials | "
        f"falls, all trials | success rate, all trials | success rate, last {settings.window} trials | best eta | "
        "wall time, s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, runs in groups.items():
        m = [r.metrics for r in runs]
        first = [x["failures_before_first_success"] for x in m]
        never = [x["failures"] for x in m if x["failures_before_first_success"] is None]
        before_k = [x["failures_before_k"] for x in m]
        short = [x["failures"] for x in m if x["failures_before_k"] is None]
        final = [moving_success_rate(r.success, settings.window)[-1] for r in runs]
        eta = _cell([x["best_eta"] for x in m])
        no_success = sum(x["best_eta"] is None for x in m)
        eta += f" ({no_success} without a success)" if no_success else ""
        lines.append(
            f"| {label} | {len(runs)} | {_cell([v for v in first if v is not None], never)} "
            f"| {_cell([v for v in before_k if v is not None], short)} "
            f"| {_cell([x['failures'] for x in m], digits='.1f')} | {_cell([x['falls'] for x in m], digits='.1f')} "
            f"| {_cell([x['success_rate'] for x in m], digits='.2f')} | {_cell(final, digits='.2f')} | {eta} "
            f"| {_cell([r.wall_s for r in runs], digits='.1f')} |"
        )
    return lines


def learn_runs(run_dirs: list[Path]) -> tuple[dict[str, dict], dict[str, Path]]:
    """The learn runs among ``run_dirs``: their scenarios and folders by run name."""
    scenarios: dict[str, dict] = {}
    folders: dict[str, Path] = {}
    for run_dir in run_dirs:
        scenario = yaml.safe_load((run_dir / "scenario.yaml").read_text())
        if scenario.get("protocol", {}).get("kind") == "learn":
            scenarios[run_dir.name] = scenario
            folders[run_dir.name] = run_dir
    return scenarios, folders


def differ(run_dirs: list[Path]) -> bool:
    """Whether the learn runs among ``run_dirs`` make two groups or more (their scenarios differ by more than the
    seed: another proposer, vigilance, any key), so that a page compares them as a study's."""
    scenarios, _ = learn_runs(run_dirs)
    return len(group_runs(scenarios)) > 1


def study_section(run_dirs: list[Path], out: Path, settings: StudySettings) -> tuple[list[str], dict]:
    """The study's Markdown lines and figures (written to ``out``) for its learn runs, and its numbers as a dict."""
    scenarios, folders = learn_runs(run_dirs)
    if not scenarios:
        return [], {}
    names = group_runs(scenarios)
    metrics = {name: run_metrics(folders[name], settings) for name in scenarios}
    complete = {
        label: [metrics[n] for n in members if metrics[n].status == "completed" and len(metrics[n].success)]
        for label, members in names.items()
    }
    left_out = [m for m in metrics.values() if m.status != "completed" or not len(m.success)]
    shown = {label: runs for label, runs in complete.items() if runs}
    lines = [
        "## Study: the groups compared",
        "",
        f"Runs grouped by what differs between their scenarios (the seed apart); each group over its completed runs "
        f"(seeds). A good gait is a success at least {settings.distinct:g} (unit cube) from every good gait before it; "
        f"K = {settings.k}. Each value is the mean and its 95 % percentile bootstrap interval over the seeds "
        "(within the values' range, so within the possible one; with few seeds it is narrower than it should be); "
        f"with {FEW} seeds or fewer that interval would be only their range, so the seeds' values are listed "
        "instead (`mean (n=2: a, b)`); a run that never got there "
        "is censored (counted apart, its total failures a lower bound), not averaged. A failure is any unsuccessful "
        "trial, a fall one whose body reports `fell`.",
        "",
    ]
    if shown:
        figures = study_figures(shown, settings, out)
        lines += [*group_table(shown, settings), "", *[f"![]({f})" for f in figures]]
    else:
        lines.append("No run completed: nothing to compare.")
    absent = {n: why for n, why in settings.said.items() if n not in metrics}
    if left_out or absent:
        count = len(left_out) + len(absent)
        lines += ["", f"Left out of every curve, box and mean: {count} runs that did not complete:", ""]
        for m in left_out:
            study = settings.said.get(m.name, "")
            study = f" (the study: {study})" if study else ""
            lines.append(f"- {m.name}: {m.status}, {m.reason or 'no trial'}{study}")
        lines += [f"- {name}: no run folder, {why}" for name, why in absent.items()]
    numbers = {
        "k": settings.k,
        "distinct": settings.distinct,
        "window": settings.window,
        "groups": {
            label: {
                "runs": [r.name for r in runs],
                "failures_before_first_success": interval_numbers(
                    [r.metrics["failures_before_first_success"] for r in runs]
                ),
                "failures_before_k": interval_numbers([r.metrics["failures_before_k"] for r in runs]),
                "censored_before_k": sum(r.metrics["failures_before_k"] is None for r in runs),
                "success_rate": interval_numbers([r.metrics["success_rate"] for r in runs]),
                "success_rate_last_window": interval_numbers(
                    [moving_success_rate(r.success, settings.window)[-1] for r in runs]
                ),
                "best_eta": interval_numbers([r.metrics["best_eta"] for r in runs]),
                "wall_time_s": interval_numbers([r.wall_s for r in runs]),
            }
            for label, runs in shown.items()
        },
        "left_out": {m.name: {"status": m.status, "reason": m.reason} for m in left_out}
        | {name: {"status": "absent", "reason": why} for name, why in absent.items()},
    }
    return lines, numbers


# --------------------------------------------------------------------------- study folders
def is_study(folder: Path) -> bool:
    """A study folder: ``study.json``, or no run of its own but run folders inside."""
    folder = Path(folder)
    if (folder / "study.json").exists():
        return True
    return (
        folder.is_dir()
        and not (folder / "scenario.yaml").exists()
        and any((child / "scenario.yaml").exists() for child in folder.iterdir() if child.is_dir())
    )


def study_runs(folder: Path) -> tuple[list[Path], dict[str, str]]:
    """A study folder's run folders (in the study's order), and how the study saw each run that did not complete,
    those without a folder too (from ``study.json``)."""
    from ..study.study import read_manifest

    folder = Path(folder)
    manifest = read_manifest(folder)
    planned = [r["name"] for r in manifest.get("runs", [])]
    found = {
        c.name: c
        for c in folder.iterdir()
        if c.is_dir() and not c.name.startswith(".") and (c / "scenario.yaml").exists()  # not a half-unpacked one
    }
    order = [n for n in planned if n in found] + sorted(n for n in found if n not in planned)
    outcomes = manifest.get("outcomes", {})
    said = {
        n: f"{o.get('status')}: {o.get('reason')}"
        for n, o in outcomes.items()
        if n in planned and o.get("status") != "completed"
    }
    said.update({n: "never run" for n in planned if n not in found and n not in said})
    return [found[n] for n in order], said


# --------------------------------------------------------------------------- comparisons and claims
def tradeoff_figure(panels: dict[str, dict[str, list[tuple[float, float]]]], path: Path) -> None:
    """Failures against best eta, one panel per walker: each group's mean (bootstrap 95 % intervals as bars) and its
    seeds (small dots); a group has the same colour and marker in every panel. ``panels``: walker -> group ->
    [(failures, best eta) per seed] (a run without a success has best eta 0)."""
    labels: list[str] = []
    for groups in panels.values():
        labels += [label for label in groups if label not in labels]
    colours = dict(zip(labels, _colours(len(labels)), strict=True))
    markers = dict(zip(labels, ("osD^v<>Pp*hX" * 4)[: len(labels)], strict=True))
    with plt.rc_context(STYLE):
        fig, axes = plt.subplots(1, len(panels), figsize=(WIDTH_IN, 3.4))
        axes = np.atleast_1d(axes)
        for ax, (walker, groups) in zip(axes, panels.items(), strict=True):
            for label, points in groups.items():
                f = np.array([p[0] for p in points], dtype=float)
                e = np.array([p[1] for p in points], dtype=float)
                fi, ei = bootstrap_mean(f), bootstrap_mean(e)
                ax.scatter(f, e, s=8, color=colours[label], alpha=0.4, lw=0)
                spread = len(f) > 1 and not np.isnan(fi.low)
                ax.errorbar(
                    fi.estimate,
                    ei.estimate,
                    xerr=[[fi.estimate - fi.low], [fi.high - fi.estimate]] if spread else None,
                    yerr=[[ei.estimate - ei.low], [ei.high - ei.estimate]] if spread else None,
                    fmt=markers[label],
                    color=colours[label],
                    ms=5,
                    capsize=2,
                    lw=1,
                    label=label,
                )
            ax.set_xlabel("failures over the budget (trials)")
            ax.set_ylabel("best eta (dimensionless)")
            ax.set_title(walker)
            ax.set_xlim(left=0)
        handles = {}
        for ax in axes:
            for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
                handles.setdefault(lab, h)
        fig.legend(list(handles.values()), list(handles), loc="lower center", ncol=2, frameon=False)
        fig.suptitle("Failures against best eta: group means with 95 % bootstrap intervals, seeds as dots")
        rows = (len(handles) + 1) // 2
        fig.set_size_inches(WIDTH_IN, 3.4 + 0.17 * rows)
        fig.tight_layout(rect=(0, 0.17 * rows / (3.4 + 0.17 * rows) + 0.02, 1, 1))
        fig.savefig(path, dpi=150, bbox_inches="tight")  # long labels: the legend whole
        plt.close(fig)


@dataclass(frozen=True)
class Claim:
    """A comparison a page makes: what it says when it holds (``says``), the test (:mod:`.stats`) and how
    the effect reads (``effect``: e.g. "ratio of failures")."""

    key: str
    says: str
    test: Test
    effect: str


def claims_table(claims: list[Claim], alpha: float = 0.05) -> tuple[list[str], dict[str, float]]:
    """The Markdown table of a page's claims with Holm's adjustment over all of them, and the adjusted p per claim.
    A claim holds when its adjusted p is below ``alpha``; one that does not is marked *not shown* (the page must not
    make it)."""
    adjusted = holm({c.key: c.test.p for c in claims})
    lines = [
        f"| # | comparison | test (seeds) | effect, 95 % CI | p | Holm p (over {len(claims)}) | at {alpha:g} |",
        "|---|---|---|---|---|---|---|",
    ]
    for i, c in enumerate(claims, 1):
        holds = adjusted[c.key] < alpha
        n = " vs ".join(str(x) for x in c.test.n)
        lines.append(
            f"| {i} | {c.says} | {c.test.name} ({n}) | {c.effect} {c.test.effect.text()} | {c.test.p:.2g} "
            f"| {adjusted[c.key]:.2g} | {'**holds**' if holds else 'not shown'} |"
        )
    return lines, adjusted
