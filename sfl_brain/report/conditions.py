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
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..recording.recorded import read_events, read_labels, read_series  # noqa: E402
from ..recording.records import read_records  # noqa: E402
from . import poincare  # noqa: E402

CONFIDENCE = 0.95


def is_conditions_run(scenario: dict) -> bool:
    return scenario.get("protocol", {}).get("kind") == "conditions"


def wilson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The Wilson score interval of a rate k / n (NaN, NaN with no trial)."""
    from scipy import stats  # here: scipy.stats costs about 0.75 s to import

    if n == 0:
        return math.nan, math.nan
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def mcnemar_exact(pairs: list[tuple[bool, bool]]) -> tuple[float, int, int]:
    """Two-sided exact McNemar test of paired outcomes (a, b): (p, pairs where only a survived, where only b did)."""
    from scipy import stats  # here: scipy.stats costs about 0.75 s to import

    only_a = sum(1 for a, b in pairs if a and not b)
    only_b = sum(1 for a, b in pairs if b and not a)
    if only_a + only_b == 0:
        return 1.0, 0, 0
    return float(stats.binomtest(only_a, only_a + only_b, 0.5).pvalue), only_a, only_b


def fisher_exact(k1: int, n1: int, k2: int, n2: int) -> float:
    """Two-sided Fisher exact test of k1 / n1 against k2 / n2."""
    from scipy import stats  # here: scipy.stats costs about 0.75 s to import

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


def outcomes_by_start(run_dir: Path) -> dict[tuple[str, int], bool]:
    """(condition, repeat) -> success of one conditions run's trials. A run of the same scenario and seed draws the
    same start for the same repeat, so two runs' outcomes pair start by start (what ``Trials.paired`` does within a
    run)."""
    trials = (r for r in read_records(run_dir) if r.get("kind") == "trial")
    return {(r["condition"], r["repeat"]): bool(r["success"]) for r in trials}


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
        elif analysis["kind"] == "pattern_space":
            from ..scenario.schema import (
                PatternSpaceAnalysis,  # its defaults (the run folder keeps the file as written)
            )

            given = PatternSpaceAnalysis.model_validate(analysis).model_dump()
            lines += pattern_space_section(t, run_dirs, given, out, f"{name}_pattern_space{k or ''}")
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


def _pick(
    t: Trials, run_dirs, analysis: dict, names: list[str], event_names: list[str], trials: int, required=None
) -> list:
    """The first ``trials`` logged trials of each condition that match ``analysis['where']`` and hold any of the
    series ``names`` (all of ``required`` if given), in condition order: (row, start, {name: Series}, [(event times
    from the start, texts)])."""
    picked: dict[str, list] = {c: [] for c in t.conditions}
    for _, rows, series, marks, starts in _logged(t, run_dirs, names, event_names):
        for trial in sorted(rows):
            row = rows[trial]
            mine = picked.setdefault(row["condition"], [])
            held = all(trial in series[n] for n in required) if required else any(trial in series[n] for n in names)
            if len(mine) >= trials or not held:
                continue
            if any(row.get(k) != v for k, v in (analysis.get("where") or {}).items()):
                continue
            start = starts.get(trial, 0.0)
            found = {n: series[n][trial] for n in names if trial in series[n]}
            happened = [(e.times - start, e.texts) for n in event_names if (e := marks[n].get(trial)) is not None]
            mine.append((row, start, found, happened))
    return [item for items in picked.values() for item in items]


def _describe(row: dict, keys: list[str]) -> str:
    return ", ".join(
        [row["condition"], *(f"{_label(k)} {_value(row.get(k))}" for k in keys), f"repeat {row['repeat']}"]
    )


def poincare_section(t: Trials, run_dirs: list[Path], out: Path, stem: str) -> list[str]:
    """E4.5's return maps of the torso pitch on every logged trial (:mod:`sfl_brain.report.poincare`): a table and the
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
    drawn = _pick(t, run_dirs, analysis, names, event_names, analysis.get("trials", 2))
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


# ------------------------------------------------------------------------------------------------ the pattern space
#: where the pattern-space figure puts an energy of 0 (a joint's RG held perfectly still, a plateau): mV^2/s (model)
ENERGY_FLOOR = 1e-6
#: the axis of the pattern space (RG potentials in the model's mV)
ENERGY_LABEL = r"log$_{10}$ E$_{RG}$, mV$^2$/s"
#: s of the trial drawn before the push
SHOWN_BEFORE = 3.0
#: the cycles before the push whose energies make the band of the gait's oscillation in the figure
BAND_CYCLES = 3


def _switched_to(scenario: dict, module: str, condition: str) -> dict[str, str]:
    """The pattern each joint switches to under ``condition`` (the switch preset its ``<module>.switch`` names, or
    the module's own ``switch``), by name or as (sigma_s, sigma_f); {} when it does not switch."""
    choice = (scenario["protocol"]["conditions"].get(condition) or {}).get(f"{module}.switch")
    params = (scenario.get("modules", {}).get(module) or {}).get("params") or {}
    if choice is None:
        preset = params.get("switch") or {}
        preset = preset if preset.get("trigger", "none") != "none" else {}
    else:
        preset = {} if choice == "none" else (params.get("switches") or {}).get(choice) or {}
    return {
        joint: p if isinstance(p, str) else f"(sigma_s {p['sigma_s']:g}, sigma_f {p['sigma_f']:g})"
        for joint, p in (preset.get("joints") or {}).items()
    }


@dataclass
class JointPath:
    """One joint's path in the pattern space on one trial: time in the trial (s), E_RG over the window before it
    (model mV^2 / s; NaN before one window has passed), and the same (4.15) of the measured joint angle (rad^2 / s,
    at its own sample times; None when the body logged no angle)."""

    time: np.ndarray
    energy: np.ndarray
    angle_time: np.ndarray | None
    angle_energy: np.ndarray | None


def value_at(time: np.ndarray, values: np.ndarray, when: float) -> float:
    """The value at the last sample at or before ``when`` (NaN past the trace's end or before its start)."""
    if when > time[-1] + 1e-9 or when < time[0] - 1e-9:
        return math.nan
    return float(values[max(0, int(np.searchsorted(time, when + 1e-9)) - 1)])


def pattern_space_paths(t: Trials, run_dirs: list[Path], analysis: dict) -> tuple[list[str], list]:
    """The data of the pattern-space figure: (joints, [(row, {joint: JointPath}, push time in the trial (s) or
    None, [(event times, texts)])]) for the first ``trials`` logged trials of each condition matching ``where``.

    E_RG(t) = (4.15) L1296 of V_E - V_F, the joint's two RG cells' potentials (the RG layer's output, as the MN
    layer's MN_E - MN_F makes the joint's command), over the ``window`` s before t (``patterns.windowed_energy``),
    from the samples the recording holds (``record.signals_hz``). The push time is the first event of
    ``events`` in the trial. Raises ValueError, naming what the recording has, for a joint without RG series."""
    from ..modules.cpg.patterns import windowed_energy
    from ..recording.recorded import read_entity_paths
    from ..registry import nearest

    module, window = analysis.get("module", "controller"), float(analysis["window"])
    runs = [Path(r) for r in run_dirs if (Path(r) / "recording.rrd").exists()]
    prefix, suffix = f"{module}/neurons/", "/E/RG_V"
    held = read_entity_paths(runs[0] / "recording.rrd") if runs else set()
    recorded = sorted(e[len(prefix) : -len(suffix)] for e in held if e.startswith(prefix) and e.endswith(suffix))
    joints = list(analysis.get("joints") or recorded)
    for joint in joints:
        if runs and joint not in recorded:
            hint = nearest(joint, recorded)
            raise ValueError(
                f"pattern_space: no RG potentials of joint {joint!r} in the recording ({prefix}{joint}/E|F/RG_V); "
                f"it holds the RGs of {recorded or 'no joint (is record.neurons true?)'}"
                + (f" (did you mean {hint!r}?)" if hint else "")
            )
    rg = {j: (f"{prefix}{j}/E/RG_V", f"{prefix}{j}/F/RG_V") for j in joints}
    angles = {j: f"body/joints/{j}" for j in joints}
    needed = [n for pair in rg.values() for n in pair]
    event_names = list(analysis.get("events") or [])
    picked = _pick(
        t, run_dirs, analysis, needed + list(angles.values()), event_names, analysis.get("trials", 1), needed
    )
    out = []
    for row, start, found, happened in picked:
        paths = {}
        for joint, (e_name, f_name) in rg.items():
            e, f = found[e_name], found[f_name]
            n = min(len(e.times), len(f.times))
            time = e.times[:n] - start
            dt = float(np.median(np.diff(time))) if n > 1 else math.nan
            energy = windowed_energy(e.values[:n] - f.values[:n], dt, window) if n > 1 else np.full(n, np.nan)
            angle = found.get(angles[joint])
            if angle is not None and len(angle.times) > 1:
                a_time = angle.times - start
                a_dt = float(np.median(np.diff(a_time)))
                a_energy = windowed_energy(np.radians(angle.values), a_dt, window)  # logged in deg
            else:
                a_time = a_energy = None
            paths[joint] = JointPath(time, energy, a_time, a_energy)
        firsts = [float(times[0]) for times, _ in happened if len(times)]
        out.append((row, paths, min(firsts) if firsts else None, happened))
    return joints, out


def _to(targets: dict[str, dict[str, str]], joint: str) -> list[str]:
    """The patterns ``joint`` switches to under any condition (``targets``: condition -> joint -> pattern)."""
    return sorted({switched[joint] for switched in targets.values() if joint in switched})


def _log(energy) -> np.ndarray:
    return np.log10(np.maximum(np.asarray(energy, dtype=float), ENERGY_FLOOR))


def pattern_space_section(t: Trials, run_dirs: list[Path], analysis: dict, out: Path, stem: str) -> list[str]:
    """Fig. 4.23 (L1430-1435): each joint's RG energy over one gait cycle against time, per condition, and every
    joint's point before the push and ``after`` s later on its own log-energy axis (the pattern space, L1298);
    two tables of the points (the RG's energy, and (4.15) of the measured joint angle)."""
    window, after = float(analysis["window"]), float(analysis.get("after", 2.0))
    try:
        joints, paths = pattern_space_paths(t, run_dirs, analysis)
    except ValueError as exc:
        return ["### The pattern space (Fig. 4.23)", "", str(exc), ""]
    if not paths:
        where = analysis.get("where") or {}
        return [
            "### The pattern space (Fig. 4.23)",
            "",
            f"No logged trial{f' with {where}' if where else ''} holds the RG potentials of {joints}.",
            "",
        ]
    module = analysis.get("module", "controller")
    targets = {c: _switched_to(t.scenario, module, c) for c in t.conditions}
    columns, head = [], []
    for row, path, push, _ in paths:
        end = float(row.get("m_time", max(p.time[-1] for p in path.values())))  # the body's trial time
        ended = "fell" if row.get("m_fell") else "ended"
        head.append(f"{row['condition']}, trial {row['trial']} ({ended} at {end:.1f} s)")
        columns.append((row, path, push, end))
    name = _pattern_space_figure(t, joints, paths, targets, window, after, out, stem)
    sampled = float(np.median(np.diff(next(iter(paths[0][1].values())).time)))
    pushes = sorted({f"{p:.2f}" for _, _, p, _ in paths if p is not None})
    lines = [
        "### The pattern space (Fig. 4.23, L1430-1435)",
        "",
        f"Each joint's pattern as its energy at the rhythm generation layer: (4.15) L1296, E = integral of "
        f"(d theta / dt)^2 dt with theta = V_E - V_F (the joint's two RG cells' potentials, model mV, sampled every "
        f"{sampled * 1000:.0f} ms), over a sliding window of {window:g} s (one gait cycle), on a log axis per joint "
        f"(L1294-1298; E = 0 drawn at {ENERGY_FLOOR:g}). Before: the window ending at the trial's first event "
        f"({', '.join(analysis['events'])}: the push, at {', '.join(pushes) or '-'} s); after: the window ending "
        f"{after:g} s "
        "later ('-': the trial ended first). Each cell: log10 E before -> after.",
        "",
        f"![]({name})",
        "",
    ]
    tables = (("RG layer, log10 E_RG (model mV^2/s)", False), ("joint angle (4.15), log10 E (rad^2/s)", True))
    for title, angle in tables:
        lines += [f"{title}:", "", "| joint | switched to | " + " | ".join(head) + " |", "|" + "---|" * (len(head) + 2)]
        for joint in joints:
            cells = [joint, ", ".join(_to(targets, joint)) or "-"]
            for _row, path, push, _end in columns:
                p = path[joint]
                time, energy = (p.angle_time, p.angle_energy) if angle else (p.time, p.energy)
                if push is None or time is None:
                    cells.append("-")
                    continue
                before, later = (value_at(time, energy, push), value_at(time, energy, push + after))
                text = [f"{float(_log(v)):.2f}" if not math.isnan(v) else "-" for v in (before, later)]
                cells.append(" -> ".join(text))
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def _pattern_space_figure(t: Trials, joints, paths, targets, window: float, after: float, out: Path, stem: str) -> str:
    ncols = 3 if len(joints) > 4 else max(1, len(joints))
    nrows = math.ceil(len(joints) / ncols)
    fig = plt.figure(figsize=(4.4 * ncols, 2.3 * nrows + 4.2))
    grid = fig.add_gridspec(nrows + 1, ncols, height_ratios=[1.0] * nrows + [1.7])
    colors = {c: plt.cm.tab10.colors[k % 10] for k, c in enumerate(t.conditions)}
    styles = ["-", "--", ":", "-."]  # one per condition, so that conditions whose RGs coincide all show
    floor = math.log10(ENERGY_FLOOR)
    keyed = []
    for row, path, push, happened in paths:
        k = t.conditions.index(row["condition"]) if row["condition"] in t.conditions else 0
        keyed.append((row, path, push, happened, colors[row["condition"]], styles[k % len(styles)]))
    top = max(float(np.nanmax(_log(p.energy))) for _, path, *_ in paths for p in path.values())
    share = None
    for j, joint in enumerate(joints):
        ax = fig.add_subplot(grid[j // ncols, j % ncols], sharex=share, sharey=share)
        share = share or ax
        band = [
            _log(p.energy[(p.time > push - BAND_CYCLES * window) & (p.time <= push)])
            for _, path, push, *_ in keyed
            if push is not None
            for p in [path[joint]]
        ]
        band = np.concatenate(band) if band else np.empty(0)
        band = band[np.isfinite(band)]
        if band.size:
            label = f"the gait's range, {BAND_CYCLES} cycles before the push"
            ax.axhspan(band.min(), band.max(), color="0.85", zorder=0, label=label)
        ax.axhline(floor, color="0.5", ls=":", lw=0.8, label=f"E = 0 (drawn at {ENERGY_FLOOR:g})")
        for row, path, _push, happened, color, style in keyed:
            p = path[joint]
            ax.plot(
                p.time,
                _log(p.energy),
                color=color,
                ls=style,
                lw=1.5,
                label=f"{row['condition']} (trial {row['trial']})",
            )
            for times, _texts in happened:
                for when in times:
                    ax.axvline(when, color=color, ls="--", lw=0.6, alpha=0.7)
        to = _to(targets, joint)
        ax.set_title(f"{joint}" + (f" -> {', '.join(to)}" if to else ""), fontsize=10)
        ax.set_ylim(floor - 0.5, top + 0.5)
        ax.grid(alpha=0.3)
        if j % ncols == 0:
            ax.set_ylabel(ENERGY_LABEL, fontsize=9)
        if j // ncols == nrows - 1 or j + ncols >= len(joints):
            ax.set_xlabel("time in the trial, s", fontsize=9)
        if j == 0:
            handles, labels = ax.get_legend_handles_labels()
    pushes = [push for _, _, push, _ in paths if push is not None]
    if pushes:  # from a little before the push: the switch, not the start
        share.set_xlim(left=max(0.0, min(pushes) - SHOWN_BEFORE))
    space = fig.add_subplot(grid[nrows, :])
    x = np.arange(len(joints))
    for row, path, push, _, color, style in keyed:
        if push is None:
            continue
        before = [value_at(path[j].time, path[j].energy, push) for j in joints]
        later = [value_at(path[j].time, path[j].energy, push + after) for j in joints]
        space.plot(
            x,
            _log(before),
            color=color,
            ls=style,
            lw=0.8,
            marker="o",
            mfc="none",
            alpha=0.6,
            label=f"{row['condition']} (trial {row['trial']}): before, the cycle ending at the push",
        )
        if not all(math.isnan(v) for v in later):
            space.plot(
                x,
                _log(later),
                color=color,
                ls=style,
                lw=1.6,
                marker="s",
                label=f"{row['condition']} (trial {row['trial']}): {after:g} s after the push",
            )
    space.axhline(floor, color="0.5", ls=":", lw=0.8)
    ticks = [j + (f"\n-> {', '.join(_to(targets, j))}" if _to(targets, j) else "") for j in joints]
    space.set_xticks(x, ticks, fontsize=8, rotation=30, ha="right", rotation_mode="anchor")
    space.set_ylabel(ENERGY_LABEL, fontsize=10)
    space.set_ylim(floor - 0.5, top + 0.5)
    space.set_title(
        f"the pattern space: one log-energy axis per joint (L1294-1298), the point before the push and {after:g} s "
        "after",
        fontsize=10,
    )
    space.grid(alpha=0.3)
    space.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.0, 0.5))
    fig.legend(handles, labels, fontsize=8, loc="upper center", ncol=min(len(labels), 4), bbox_to_anchor=(0.5, 1.0))
    fig.suptitle(
        f"{t.scenario['name']}: energy (4.15) of each joint's RG output V_E - V_F over the last {window:g} s (one gait "
        f"cycle), from {SHOWN_BEFORE:g} s before the push; dashed verticals: the push and the switch",
        fontsize=11,
        y=1.03,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    name = f"{stem}.png"
    fig.savefig(out / name, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return name
