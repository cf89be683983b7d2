"""``sfl report`` for issue 29's terrain walks: what a terrain switch did to the commands, and how the detectors of a
change of terrain compare (analyses ``command_jump`` and ``detection`` of a conditions run; the recording holds both).

- ``command_jump``: the controller records, for every tick its terrain switch moves parameters, the largest change of
  any joint's command the switch itself made (``<module>/terrain_switch/command_jump``, rad); per condition, the
  switches seen and their largest such change against the analysis's ``limit``.
- ``detection``: the controller's watched detectors (``<module>/events/detector``, "detector NAME: ...") against the
  body's mark of a foot first touching the next piece of ground (``body/events/terrain``) and the torso pitch
  (``body/torso/pitch``, deg): per condition and detector, the walks it fired on, those before the change (false
  alarms), its latency after the change, and those within ``latency`` s and before the pitch fell below
  ``pitch_below`` deg.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .conditions import Trials, _logged, _rate

DETECTOR_ORDER = ("torso", "pitch_rate", "phase_pitch", "foot_slope", "ankle_error", "time")


def command_jump_section(t: Trials, run_dirs: list[Path], analysis: dict) -> list[str]:
    """The table of the switches' command changes per condition (every logged trial)."""
    name = f"{analysis.get('module', 'controller')}/terrain_switch/command_jump"
    limit = float(analysis.get("limit", 0.02))
    logged: dict[str, int] = {c: 0 for c in t.conditions}
    switched: dict[str, list[float]] = {c: [] for c in t.conditions}
    for _run, rows, series, _marks, _starts in _logged(t, run_dirs, [name]):
        for trial, row in rows.items():
            logged[row["condition"]] += 1
            jumps = series[name].get(trial)
            if jumps is not None and len(jumps.values):
                switched[row["condition"]].append(float(np.max(jumps.values)))
    lines = [
        "### What the switch did to the commands",
        "",
        f"Per logged trial, the largest change of any joint's command that the terrain switch itself made in one tick "
        f"(the state held; `{name}`), against {limit:g} rad.",
        "",
        "| condition | logged trials | trials that switched | largest change, rad | trials over the limit |",
        "|---|---|---|---|---|",
    ]
    for c in t.conditions:
        jumps = switched[c]
        largest = f"{max(jumps):.2g}" if jumps else "-"
        over = sum(j > limit for j in jumps)
        lines.append(f"| {c} | {logged[c]} | {len(jumps)} | {largest} | {over} |")
    return lines + [""]


def _first_below(series, after: float, level: float) -> float | None:
    """The first time at or after ``after`` that ``series`` is below ``level``, or None."""
    if series is None:
        return None
    mine = (series.times >= after - 1e-9) & (series.values < level)
    return float(series.times[np.argmax(mine)]) if mine.any() else None


def detector_of(text: str) -> str:
    """The detector a controller's ``events/detector`` line names (``detector NAME: ...``, ``detector_text``)."""
    return text.split(":")[0].removeprefix("detector ")


def fired_early(row: dict) -> bool:
    """A detection row's detector fired before a foot met the next ground (on a walk that met none: at all)."""
    return row["fired"] is not None and (row["reached"] is None or row["fired"] < row["reached"])


def fired_in_time(row: dict, latency: float) -> bool:
    """A detection row's detector fired within ``latency`` s after a foot met the next ground, and not after the
    torso pitched past its limit (``row["pitch"]``)."""
    fired, reached = row["fired"], row["reached"]
    if reached is None or fired is None or fired < reached:
        return False
    return fired - reached <= latency + 1e-9 and (row["pitch"] is None or fired <= row["pitch"])


def detection_rows(t: Trials, run_dirs: list[Path], analysis: dict) -> list[dict]:
    """One row per logged trial and watched detector: trial, condition, detector, fired (s of the trial or None),
    reached (when a foot met the next ground, or None), pitch (when the torso pitch first fell below ``pitch_below``
    after the change, or None)."""
    module = analysis.get("module", "controller")
    events = [f"{module}/events/detector", "body/events/terrain"]
    out = []
    for _run, rows, series, marks, starts in _logged(t, run_dirs, ["body/torso/pitch"], events):
        watched = sorted({detector_of(text) for e in marks[events[0]].values() for text in e.texts})
        for trial, row in rows.items():
            if trial not in starts:
                continue  # not logged
            start = starts[trial]
            terrain = marks[events[1]].get(trial)
            reached = float(terrain.times[0] - start) if terrain is not None and len(terrain.times) else None
            pitch = series["body/torso/pitch"].get(trial)
            below = None
            if reached is not None and pitch is not None:
                when = _first_below(pitch, start + reached, float(analysis.get("pitch_below", -5.0)))
                below = None if when is None else when - start
            fired: dict[str, float] = {}
            found = marks[events[0]].get(trial)
            for when, text in zip(found.times, found.texts, strict=True) if found is not None else ():
                fired.setdefault(detector_of(text), float(when - start))
            for detector in watched:
                out.append(
                    {
                        "trial": trial,
                        "condition": row["condition"],
                        "detector": detector,
                        "fired": fired.get(detector),
                        "reached": reached,
                        "pitch": below,
                    }
                )
    return out


def detection_section(t: Trials, run_dirs: list[Path], analysis: dict) -> list[str]:
    """The detectors' table (see the module docstring) and a summary over the walks that changed terrain."""
    rows = detection_rows(t, run_dirs, analysis)
    if not rows:
        return ["### Detecting the change of terrain", "", "No logged trial holds a watched detector.", ""]
    limit, level = float(analysis.get("latency", 0.5)), float(analysis.get("pitch_below", -5.0))
    detectors = sorted({r["detector"] for r in rows}, key=lambda d: (DETECTOR_ORDER + (d,)).index(d))
    lines = [
        "### Detecting the change of terrain",
        "",
        f"Every detector watched on every logged walk (none switches). *Change*: a foot first touches the next piece "
        f"of ground. *In time*: fired within {limit:g} s after the change and before the torso pitch fell below "
        f"{level:g} deg. *Early*: fired before the change (on the flat walk: at all), a false alarm. Latency: median "
        "[range] over the walks it fired on after the change.",
        "",
        "| condition | detector | walks | changed | fired early | fired after the change | latency, s | in time |",
        "|---|---|---|---|---|---|---|---|",
    ]
    summary = {d: [0, 0, 0, 0] for d in detectors}  # in time, changed walks, early, all walks
    for c in t.conditions:
        for d in detectors:
            mine = [r for r in rows if r["condition"] == c and r["detector"] == d]
            if not mine:
                continue
            changed = [r for r in mine if r["reached"] is not None]
            early = [r for r in mine if fired_early(r)]
            after = [r for r in changed if r["fired"] is not None and r["fired"] >= r["reached"]]
            latency = [r["fired"] - r["reached"] for r in after]
            in_time = [r for r in after if fired_in_time(r, limit)]
            shown = f"{np.median(latency):.2f} [{min(latency):.2f}, {max(latency):.2f}]" if latency else "-"
            lines.append(
                f"| {c} | {d} | {len(mine)} | {len(changed)} | {len(early)} | {len(after)} | {shown} | "
                f"{len(in_time)}/{len(changed) if changed else 0} |"
            )
            summary[d][0] += len(in_time)
            summary[d][1] += len(changed)
            summary[d][2] += len(early)
            summary[d][3] += len(mine)
    lines += [
        "",
        "Over every walk that changed terrain, and every walk for the false alarms (Wilson 95% intervals):",
        "",
        "| detector | in time | fired early (false alarms) |",
        "|---|---|---|",
    ]
    for d in detectors:
        in_time, changed, early, walks = summary[d]
        lines.append(f"| {d} | {_rate(in_time, changed)} | {_rate(early, walks)} |")
    return lines + [""]


def terrain_sections(scenario: dict, run_dirs: list[Path]) -> list[str]:
    """The sections of a conditions run's ``command_jump`` and ``detection`` analyses (after ``conditions_section``)."""
    analyses = [a for a in scenario["protocol"].get("analyses") or [] if a["kind"] in ("command_jump", "detection")]
    if not analyses:
        return []
    t = Trials(scenario, run_dirs)
    lines: list[str] = []
    for analysis in analyses:
        section = command_jump_section if analysis["kind"] == "command_jump" else detection_section
        lines += section(t, run_dirs, analysis)
    return lines
