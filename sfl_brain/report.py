"""``sfl report``: figures (PNG) and a Markdown table for finished runs.

* a sweep run: the viability map over the first two axes (success coloured by walking speed);
* a learn run: both maps after learning (from ``acc.npz``) over the tried points;
* for every run a table row: protocol, vigilance, trials, success rate, next to the thesis's figure.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402

from .records import read_records, summarise  # noqa: E402

THESIS_E32 = {0.05: "98%", 0.0: "96%", -0.1: "45%", -0.2: "28%"}


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
        ax.set_title(f"{scenario['name']}: {ok.mean():.0%} success in {len(ok)} trials")
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


def write_report(run_dirs: list[Path], out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    lines = ["| run | protocol | s_vig | trials | success rate | thesis | figure |", "|---|---|---|---|---|---|---|"]
    for run_dir in run_dirs:
        scenario = yaml.safe_load((run_dir / "scenario.yaml").read_text())
        rows = read_records(run_dir)
        summary = summarise(rows)
        vig = scenario.get("modules", {}).get("vigilance", {}).get("params", {})
        s_vig = vig.get("value") if vig.get("mode", "fixed") == "fixed" else vig.get("mode")
        thesis = THESIS_E32.get(s_vig, "") if scenario["protocol"]["kind"] == "learn" else ""
        figure = _figure(run_dir, out, scenario, rows)
        rate = summary["success_rate"]
        lines.append(f"| {run_dir.name} | {scenario['protocol']['kind']} | {s_vig if s_vig is not None else '-'} | "
                     f"{summary['trials']} | {'-' if rate is None else f'{rate:.1%}'} | {thesis} | "
                     f"{f'![]({figure})' if figure else ''} |")
    path = out / "README.md"
    path.write_text("# Results\n\n" + "\n".join(lines) + "\n")
    (out / "summary.json").write_text(json.dumps({str(d): summarise(read_records(d)) for d in run_dirs}, indent=1))
    return path
