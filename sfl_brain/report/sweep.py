"""``sfl report`` for sweeps over a grid of two or three axes: which cells succeed and how well.

A sweep (``protocol.kind: sweep``) runs every point of a grid over Omega once. Its section shows:

* a figure: one panel per value of the third axis (one panel for two axes); in each, the grid of the first two axes
  in their physical units, a success coloured by its quality eta (the efficiency of (5.8) for the walkers), a failure
  grey and marked by how it ended (F fell, L left the lane, T timed out, S stood, when the body says);
* a table: successes per value of the last axis and overall, and the spread of eta among the successes (lowest,
  highest, their ratio): what chapter 5's pre-sweep must show before learning (issue 21: 30-70% of the grid walks,
  the walking cells differing in efficiency by at least 2x).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def is_grid_sweep(scenario: dict) -> bool:
    return scenario.get("protocol", {}).get("kind") == "sweep" and len(scenario.get("space", [])) in (2, 3)


#: how a failure ended, as the figure marks it
ENDINGS = (("F", "fell"), ("L", "left the lane"), ("T", "timed out"), ("S", "stood"), ("x", "other"))


def _ending(row: dict) -> str:
    if row.get("success"):
        return ""
    if row.get("m_fell"):
        return "F"
    if row.get("m_left_lane"):
        return "L"
    if row.get("m_timed_out"):
        return "T"
    if row.get("m_steps") is not None:
        return "S"
    return "x"


def _axis_label(axis: dict) -> str:
    return f"{axis['name']}, {axis['unit']}" if axis.get("unit") else axis["name"]


def sweep_section(run_dir: Path, out: Path, scenario: dict, rows: list[dict]) -> list[str]:
    """The Markdown section (and figure in ``out``) of one grid sweep."""
    axes = scenario["space"]
    trials = [r for r in rows if r.get("kind") == "trial" and r.get("v_unit") is not None]
    if not trials:
        return []
    names = [a["name"] for a in axes]
    values = [sorted({r[n] for r in trials}) for n in names]
    third = values[2] if len(axes) == 3 else [None]
    fig, panels = plt.subplots(
        1, len(third), figsize=(3.4 * len(third) + 1.2, 3.6), squeeze=False, sharey=True, constrained_layout=True
    )
    etas = [r["quality"] for r in trials if r.get("success") and r.get("quality") is not None]
    low, high = (min(etas), max(etas)) if etas else (0.0, 1.0)
    scatter = None
    for k, level in enumerate(third):
        ax = panels[0, k]
        mine = [r for r in trials if level is None or r[names[2]] == level]
        ok = [r for r in mine if r.get("success")]
        bad = [r for r in mine if not r.get("success")]
        if bad:
            ax.scatter([r[names[0]] for r in bad], [r[names[1]] for r in bad], s=90, c="0.85", marker="s")
            for r in bad:
                ax.annotate(_ending(r), (r[names[0]], r[names[1]]), ha="center", va="center", fontsize=8, color="0.3")
        if ok:
            scatter = ax.scatter(
                [r[names[0]] for r in ok],
                [r[names[1]] for r in ok],
                s=90,
                c=[r["quality"] for r in ok],
                cmap="viridis",
                vmin=low,
                vmax=high,
                marker="s",
            )
        ax.set_xlabel(_axis_label(axes[0]), fontsize=10)
        title = f"{names[2]} = {level:g}" if level is not None else scenario["name"]
        ax.set_title(f"{title}: {len(ok)}/{len(mine)} succeed", fontsize=10)
    panels[0, 0].set_ylabel(_axis_label(axes[1]), fontsize=10)
    if scatter is not None:
        fig.colorbar(scatter, ax=panels[0, :].tolist(), label="eta of a success (5.8)", shrink=0.9)
    name = f"{run_dir.name}_grid.png"
    fig.savefig(out / name, dpi=110)
    plt.close(fig)
    successes = sum(1 for r in trials if r.get("success"))
    lines = [
        f"## {scenario['name']}: the grid",
        "",
        f"{successes} of {len(trials)} cells succeed ({successes / len(trials):.0%}). Failures: "
        + ", ".join(
            f"{label} {sum(1 for r in trials if _ending(r) == code)}"
            for code, label in ENDINGS
            if any(_ending(r) == code for r in trials)
        )
        + ".",
        "",
    ]
    if etas:
        lines += [
            f"eta among the successes: lowest {low:.4g}, highest {high:.4g}, ratio {high / low:.2f}"
            if low > 0
            else f"eta among the successes: lowest {low:.4g}, highest {high:.4g}",
            "",
        ]
    if len(axes) == 3:
        lines += [f"| {names[2]} | successes | eta lowest | eta highest |", "|---|---|---|---|"]
        for level in third:
            mine = [r for r in trials if r[names[2]] == level]
            good = [r["quality"] for r in mine if r.get("success")]
            span = f"{min(good):.4g} | {max(good):.4g}" if good else "- | -"
            lines.append(f"| {level:g} | {len(good)}/{len(mine)} | {span} |")
        lines.append("")
    lines += [f"![]({name})", ""]
    return lines
