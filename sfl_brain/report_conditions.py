"""``sfl report`` for runs of the conditions protocol: survival per condition, with intervals and exact tests.

A conditions run (``protocol.kind: conditions``) runs every named condition at every point of a grid of trial
parameters, ``repeats`` times from the same starts (see :func:`sfl_brain.protocols.run_conditions`). Its report,
per scenario (runs of one scenario with other seeds are pooled: more starts):

* a summary table: one row per point of the grid's keys that are not pooled (``protocol.pool``, e.g. the gait
  phase), one column per condition: survived / trials, the rate and its Wilson 95% interval; then one exact test
  per pair of ``protocol.compare``: McNemar's exact test on the paired trials (the same run, grid point and repeat
  under both conditions; a binomial test on the pairs where exactly one survived), and Fisher's exact test on the
  two counts as if unpaired;
* the same per grid point (pooled keys included);
* the mean (and spread) of the body metrics ``protocol.metrics`` names, per condition and row;
* figures: survival against the first non-pooled grid key and against the first pooled one, one line per
  condition with its Wilson band.

"Survived" is the trial's ``survived`` column (``protocol.judge``: the body's success, or no fall). Only completed
runs enter the tables; the others are listed as left out.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from . import poincare  # noqa: E402
from .recorded import read_events, read_labels, read_series  # noqa: E402
from .records import read_records  # noqa: E402

CONFIDENCE = 0.95


def is_conditions_run(scenario: dict) -> bool:
    return scenario.get("protocol", {}).get("kind") == "conditions"


def wilson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The Wilson score interval of a rate k / n (NaN, NaN with no trial)."""
    if n == 0:
        return math.nan, math.nan
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def mcnemar_exact(pairs: list[tuple[bool, bool]]) -> tuple[float, int, int]:
    """Two-sided exact McNemar test of paired outcomes (a, b): (p, pairs where only a survived, where only b did)."""
    only_a = sum(1 for a, b in pairs if a and not b)
    only_b = sum(1 for a, b in pairs if b and not a)
    if only_a + only_b == 0:
        return 1.0, 0, 0
    return float(stats.binomtest(only_a, only_a + only_b, 0.5).pvalue), only_a, only_b


def fisher_exact(k1: int, n1: int, k2: int, n2: int) -> float:
    """Two-sided Fisher exact test of k1 / n1 against k2 / n2."""
    if n1 == 0 or n2 == 0:
        return math.nan
    return float(stats.fisher_exact([[k1, n1 - k1], [k2, n2 - k2]]).pvalue)


def _rate(k: int, n: int) -> str:
    if n == 0:
        return "-"
    low, high = wilson(k, n)
    return f"{k}/{n} = {k / n:.0%} [{low:.0%}, {high:.0%}]"


def _p(p: float) -> str:
    if math.isnan(p):
        return "-"
    return f"{p:.2g}" if p >= 0.001 else f"{p:.1e}"


def _label(key: str) -> str:
    return key.partition(".")[2] or key


def _value(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


class Trials:
    """The trials of a scenario's completed conditions runs, with what its protocol says about them."""

    def __init__(self, scenario: dict, run_dirs: list[Path]) -> None:
        proto = scenario["protocol"]
        self.scenario = scenario
        self.conditions: list[str] = list(proto["conditions"])
        self.grid: dict[str, list] = dict(proto.get("grid") or {})
        self.pool: list[str] = list(proto.get("pool") or [])
        self.compare: list[tuple[str, str]] = [tuple(p) for p in proto.get("compare") or []]
        self.metrics: list[str] = list(proto.get("metrics") or [])
        self.judge: str = proto.get("judge", "success")
        self.kept = [k for k in self.grid if k not in self.pool]
        self.rows: list[dict] = []
        for run in run_dirs:
            for row in read_records(run):
                if row.get("kind") == "trial":
                    self.rows.append({**row, "_run": str(run)})

    def select(self, condition: str, where: dict) -> list[dict]:
        return [
            r for r in self.rows if r.get("condition") == condition and all(r.get(k) == v for k, v in where.items())
        ]

    def points(self, keys: list[str]) -> list[dict]:
        """Every combination of the values of ``keys`` (in the grid's order)."""
        return [dict(zip(keys, values, strict=True)) for values in itertools.product(*(self.grid[k] for k in keys))]

    @staticmethod
    def count(rows: list[dict]) -> tuple[int, int]:
        return sum(1 for r in rows if r.get("survived")), len(rows)

    def paired(self, a: str, b: str, where: dict) -> list[tuple[bool, bool]]:
        """Outcomes of the same run, grid point and repeat under conditions a and b."""

        def key(r: dict) -> tuple:
            return (r["_run"], r.get("repeat"), *(r.get(k) for k in self.grid))

        first = {key(r): bool(r.get("survived")) for r in self.select(a, where)}
        second = {key(r): bool(r.get("survived")) for r in self.select(b, where)}
        return [(first[k], second[k]) for k in first if k in second]

    def table(self, keys: list[str]) -> list[str]:
        """Survival per condition for every combination of ``keys``, and the exact tests of ``compare``."""
        head = [_label(k) for k in keys] + self.conditions
        for a, b in self.compare:
            head += [f"{a} vs {b}: McNemar p (only {a} / only {b})", "Fisher p"]
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for where in self.points(keys) or [{}]:
            cells = [_value(where[k]) for k in keys]
            counts = {c: self.count(self.select(c, where)) for c in self.conditions}
            cells += [_rate(*counts[c]) for c in self.conditions]
            for a, b in self.compare:
                p, only_a, only_b = mcnemar_exact(self.paired(a, b, where))
                cells += [f"{_p(p)} ({only_a} / {only_b})", _p(fisher_exact(*counts[a], *counts[b]))]
            lines.append("| " + " | ".join(cells) + " |")
        return lines

    def metric_table(self) -> list[str]:
        if not self.metrics:
            return []
        head = [_label(k) for k in self.kept] + ["condition"] + [f"{m}: mean (sd)" for m in self.metrics]
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for where in self.points(self.kept) or [{}]:
            for c in self.conditions:
                rows = self.select(c, where)
                cells = [_value(where[k]) for k in self.kept] + [c]
                for name in self.metrics:
                    values = [r.get(f"m_{name}", r.get(name)) for r in rows]  # a body metric, or quality
                    values = [float(v) for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
                    cells.append(f"{np.mean(values):.3g} ({np.std(values):.2g})" if values else "-")
                lines.append("| " + " | ".join(cells) + " |")
        return lines

    def figure(self, key: str, out: Path, stem: str) -> str:
        """Survival against grid key ``key`` (pooled over the others), one line and Wilson band per condition."""
        values = self.grid[key]
        numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
        x = np.asarray(values, dtype=float) if numeric else np.arange(len(values))
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for c in self.conditions:
            rates, lows, highs = [], [], []
            for v in values:
                k, n = self.count(self.select(c, {key: v}))
                low, high = wilson(k, n)
                rates.append(k / n if n else math.nan)
                lows.append(low)
                highs.append(high)
            (line,) = ax.plot(x, rates, marker="o", label=c)
            ax.fill_between(x, lows, highs, color=line.get_color(), alpha=0.15)
        if not numeric:
            ax.set_xticks(x, [str(v) for v in values])
        ax.set_xlabel(_label(key), fontsize=11)
        ax.set_ylabel("survived (upright)" if self.judge == "upright" else "success", fontsize=11)
        ax.set_ylim(-0.03, 1.03)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=9, title=f"{CONFIDENCE:.0%} Wilson bands", title_fontsize=9)
        ax.set_title(f"{self.scenario['name']}: {len(self.rows)} trials", fontsize=11)
        fig.tight_layout()
        name = f"{stem}_{_label(key)}.png"
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        return name


def conditions_section(scenario: dict, run_dirs: list[Path], left_out: list[str], out: Path) -> list[str]:
    """The Markdown section (and figures in ``out``) of one scenario's completed conditions runs."""
    t = Trials(scenario, run_dirs)
    name = scenario["name"]
    repeats = scenario["protocol"].get("repeats", 1)
    lines = [
        f"## {name}: trials under named conditions",
        "",
        scenario.get("description", "").strip(),
        "",
        f"{len(run_dirs)} completed run(s) (seeds {sorted({_seed(r) for r in run_dirs})}), {repeats} repeat(s) each: "
        f"{len(t.rows)} trials. Verdict: {'no fall (upright)' if t.judge == 'upright' else 'the body success'}. "
        f"Rates with their Wilson {CONFIDENCE:.0%} intervals; McNemar's exact test pairs the same start under two "
        "conditions, Fisher's exact test compares the counts unpaired.",
        "",
    ]
    for c in t.conditions:
        params = scenario["protocol"]["conditions"][c] or {}
        shown = ", ".join(f"`{k}` = {_value(v)}" for k, v in params.items()) or "the scenario as it is"
        lines.append(f"- **{c}**: {shown}")
    lines.append("")
    pooled = f" (pooled over {', '.join(_label(k) for k in t.pool)} and the repeats)" if t.pool else ""
    lines += [f"### Survival by {', '.join(_label(k) for k in t.kept) or 'condition'}{pooled}", ""]
    lines += t.table(t.kept) + [""]
    if t.pool:
        lines += [f"### Survival at every grid point ({', '.join(_label(k) for k in t.grid)})", ""]
        lines += t.table(list(t.grid)) + [""]
    metrics = t.metric_table()
    if metrics:
        lines += ["### Body metrics", ""] + metrics + [""]
    for key in ([t.kept[0]] if t.kept else []) + ([t.pool[0]] if t.pool else []):
        lines += [f"![]({t.figure(key, out, name)})", ""]
    for k, analysis in enumerate(scenario["protocol"].get("analyses") or []):
        if analysis["kind"] == "poincare":
            lines += poincare_section(t, run_dirs, out, f"{name}_poincare{k or ''}")
        elif analysis["kind"] == "trace":
            lines += trace_section(t, run_dirs, analysis, out, f"{name}_trace{k or ''}")
    if left_out:
        lines += ["Left out (did not complete):", ""] + [f"- {text}" for text in left_out] + [""]
    return lines


def _seed(run_dir: Path) -> int | str:
    import yaml

    try:
        return yaml.safe_load((Path(run_dir) / "scenario.yaml").read_text()).get("seed", "?")
    except (OSError, AttributeError):
        return "?"


# ------------------------------------------------------------------------------------------------ from the recording
def _logged(t: Trials, run_dirs: list[Path], entities: list[str], events: list[str] = ()):
    """Per run: its rows by trial, the series and events of its logged trials, and where each trial starts on
    sim_time (its first ``body/trial/events`` event)."""
    for run in run_dirs:
        rrd = Path(run) / "recording.rrd"
        if not rrd.exists():
            continue
        rows = {r["trial"]: r for r in t.rows if r["_run"] == str(run)}
        marks = read_events(rrd, ["body/trial/events", *events])
        starts = {trial: float(e.times[0]) for trial, e in marks["body/trial/events"].items()}
        yield run, rows, read_series(rrd, entities), marks, starts


def _describe(row: dict, keys: list[str]) -> str:
    return ", ".join(
        [row["condition"], *(f"{_label(k)} {_value(row.get(k))}" for k in keys), f"repeat {row['repeat']}"]
    )


def poincare_section(t: Trials, run_dirs: list[Path], out: Path, stem: str) -> list[str]:
    """E4.5's return maps of the torso pitch on every logged trial (:mod:`sfl_brain.poincare`): a table and the
    figure (the phase diagram of the first walk, every walk's cobweb, every walk's path)."""
    names = ["body/torso/pitch", "body/torso/pitch_rate", "body/path/x", "body/path/y"]
    walks = []
    for _run, rows, series, _, starts in _logged(t, run_dirs, names):
        for trial in sorted(series["body/torso/pitch"]):
            if trial not in rows or trial not in series["body/torso/pitch_rate"]:
                continue
            pitch, rate = series["body/torso/pitch"][trial], series["body/torso/pitch_rate"][trial]
            time = pitch.times - starts.get(trial, pitch.times[0])
            result = poincare.analyse(time, np.radians(pitch.values), np.radians(rate.values))
            path = [series[n].get(trial) for n in ("body/path/x", "body/path/y")]
            walks.append((rows[trial], time, np.radians(pitch.values), np.radians(rate.values), result, path))
    if not walks:
        return ["### Poincaré return maps", "", "No logged trial with the torso's pitch and its rate.", ""]
    sampled = float(np.median(np.diff(walks[0][1])))
    lines = [
        "### Poincaré return maps of the torso pitch (E4.5)",
        "",
        f"Sigma: pitch rate = 0, + to - (the pitch's maxima), sampled every {sampled * 1000:.0f} ms. Step map r_(n+1) "
        "against r_n over every crossing; stride maps A, B: every second crossing (one per gait cycle). r* and slope "
        f"b of the least-squares line; steady: after {poincare.SETTLE:g} s; settled after: returns before the last "
        "one more than 3 s.d. from the steady mean.",
        "",
        "| trial | walk | ended | time s | returns | r_0 | r_1 | r_2 | r_3 | steady mean +- s.d. | settled after | "
        "step map r*, b | steady r*, b | stride A r*, b | stride B r*, b |",
        "|" + "---|" * 15,
    ]
    for row, time, _, _, res, _ in walks:
        ended = "fell" if row.get("m_fell") else "left the lane" if row.get("m_left_lane") else "timed out"
        if row.get("success"):
            ended = "reached the line"
        head = f"| {row['trial']} | {_describe(row, list(t.grid))} | {ended} | {time[-1]:.1f} |"
        if res is None:
            lines.append(head + " < 3 |" + " - |" * 10)
            continue
        r = res["returns"]
        first = " | ".join(f"{v:.4f}" for v in r[:4]) + " | -" * (4 - min(4, len(r)))
        maps = (res["map"], res["steady_map"], *res["branches"])
        cells = [f"{m.fixed_point:.4f}, {m.slope:+.2f} +- {m.slope_error:.2f}" if m else "-" for m in maps]
        settled = min(res["settled_after"], len(res["times"]) - 1)
        lines.append(
            f"{head} {len(r)} | {first} | {res['steady_mean']:.4f} +- {res['steady_sd']:.4f} | "
            f"{res['settled_after']} ({res['times'][settled]:.1f} s) | {' | '.join(cells)} |"
        )
    stable = [res["map"].stable for *_, res, _ in walks if res is not None]
    lines += ["", f"Step maps stable (|b| < 1): {sum(stable)} of {len(stable)} walks.", ""]
    lines += [f"![]({_poincare_figure(walks, out, stem)})", ""]
    return lines


def _poincare_figure(walks, out: Path, stem: str) -> str:
    fig, (phase, web, ground) = plt.subplots(1, 3, figsize=(16, 5.2), gridspec_kw={"width_ratios": [1, 1, 0.8]})
    colors = plt.cm.tab10.colors
    row, time, pitch, rate, result, _ = walks[0]
    phase.plot(pitch, rate, lw=0.3, color="0.6", label="(pitch, pitch rate)")
    early = time < 5.0
    phase.plot(pitch[early], rate[early], lw=1.0, color=colors[0], label="first 5 s")
    if result is not None:
        phase.plot(result["returns"], np.zeros_like(result["returns"]), "|", color="k", label="section returns r_n")
    phase.set_xlabel("torso pitch, rad (+ = forward)", fontsize=11)
    phase.set_ylabel("torso pitch rate, rad/s", fontsize=11)
    phase.set_title(f"phase diagram, trial {row['trial']}, {time[-1]:.0f} s", fontsize=11)
    phase.legend(fontsize=8)
    done = [w for w in walks if w[4] is not None]
    if done:
        every = np.concatenate([w[4]["returns"] for w in done])
        low, high = float(every.min()), float(every.max())
        margin = 0.05 * (high - low)
        web.plot([low - margin, high + margin], [low - margin, high + margin], "k--", lw=0.8, label="diagonal")
        for k, w in enumerate(done):
            poincare.cobweb(web, w[4]["returns"], w[4]["map"], colors[k % 10], f"trial {w[0]['trial']}")
    web.set_xlabel("r_n, rad", fontsize=11)
    web.set_ylabel("r_(n+1), rad", fontsize=11)
    web.set_title("step map on pitch rate = 0 (+ to -), cobweb of r_0..r_6", fontsize=11)
    web.legend(fontsize=7)
    for k, w in enumerate(walks):
        x, y = w[5]
        if x is not None and y is not None:
            ground.plot(x.values, y.values, lw=0.8, color=colors[k % 10], label=f"trial {w[0]['trial']}")
    ground.set_xlabel("x, m", fontsize=11)
    ground.set_ylabel("y, m", fontsize=11)
    ground.set_title("the torso's path (top view)", fontsize=11)
    ground.legend(fontsize=7)
    fig.tight_layout()
    name = f"{stem}.png"
    fig.savefig(out / name, dpi=100)
    plt.close(fig)
    return name


def trace_section(t: Trials, run_dirs: list[Path], analysis: dict, out: Path, stem: str) -> list[str]:
    """The recorded series of the first ``trials`` logged trials of each condition, one panel per series, the
    events marked as vertical lines (their text in the table below the figure)."""
    names, event_names = list(analysis["series"]), list(analysis.get("events") or [])
    picked: dict[str, list] = {c: [] for c in t.conditions}
    for _, rows, series, marks, starts in _logged(t, run_dirs, names, event_names):
        for trial in sorted(rows):
            row = rows[trial]
            mine = picked.setdefault(row["condition"], [])
            if len(mine) >= analysis.get("trials", 2) or not any(trial in series[n] for n in names):
                continue
            if any(row.get(k) != v for k, v in (analysis.get("where") or {}).items()):
                continue
            start = starts.get(trial, 0.0)
            found = {n: series[n][trial] for n in names if trial in series[n]}
            happened = [(e.times - start, e.texts) for n in event_names if (e := marks[n].get(trial)) is not None]
            mine.append((row, start, found, happened))
    drawn = [item for items in picked.values() for item in items]
    if not drawn:
        return ["### Recorded traces", "", f"No logged trial holds {names}.", ""]
    fig, axes = plt.subplots(len(names), 1, figsize=(10, 2.6 * len(names) + 0.8), sharex=True, squeeze=False)
    colors = plt.cm.tab10.colors
    table = ["| trial | condition | event time s | event |", "|---|---|---|---|"]
    for k, (row, start, found, happened) in enumerate(drawn):
        color = colors[k % 10]
        label = f"trial {row['trial']} ({_describe(row, list(t.grid))})"
        for ax, name in zip(axes[:, 0], names, strict=True):
            if name in found:
                ax.plot(found[name].times - start, found[name].values, lw=0.9, color=color, label=label)
            for times, _texts in happened:
                for when in times:
                    ax.axvline(when, color=color, ls="--", lw=0.8)
        for times, texts in happened:
            table += [
                f"| {row['trial']} | {row['condition']} | {w:.2f} | {text} |"
                for w, text in zip(times, texts, strict=True)
            ]
    labels = read_labels(Path(run_dirs[0]) / "recording.rrd", names) if run_dirs else {}
    for ax, name in zip(axes[:, 0], names, strict=True):
        ax.set_ylabel(labels.get(name, name.rpartition("/")[2]), fontsize=10)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time in the trial, s (dashed: events)", fontsize=11)
    fig.tight_layout()
    name = f"{stem}.png"
    fig.savefig(out / name, dpi=100)
    plt.close(fig)
    lines = ["### Recorded traces", "", f"![]({name})", ""]
    return lines + (table + [""] if len(table) > 2 else [])
