"""E3.5 over a family of random terrains: switching success neurons against every fixed setting.

    python docs/experiments/e3_5_terrains.py [--terrains 12] [--maps runs/chapter3/e3_4_s0/acc.npz]
                                             [--out runs/e3_5_terrains] [--table docs/results/e3_5_terrains.md]

The thesis's claim (Figs. 3.16-3.18) is that switching between the success map's neurons by the
slope under the robot lets the walker cross terrain a single fixed (alpha, theta) cannot. One
terrain can be chosen to make any controller look good or bad, so this script draws a family of
terrains from fixed rules, decided before any of them was run, and runs on each of them:

- the switching controller of ``scenarios/e3_5_terrain.yaml`` (the E3.4 s_vig 0 map), one trial
  (the walker is deterministic: repeated trials are identical);
- every fixed (alpha, theta) of the 21 x 21 grid of ``scenarios/e3_5_fixed.yaml``.

Terrain k (seed k = 1..N): 0.5 m flat, then pieces of U[1.0, 2.5] m (0.1 m steps) with an integer
slope drawn uniformly from -10..+5 deg, until the profile is at least 8.5 m long. The range stops
at +5 deg because climbs steeper than that defeat most of the walker's gaits (E3.4: 0-45% walk at
+5 deg) and the s_vig 0 map has only one success neuron above +1.8 deg. Success is E3.5's:
7.5 m forward in 15 s without falling.

It prints and writes a Markdown table: per terrain, whether switching crossed and how many fixed
settings crossed; then, over the family, the fixed settings that cross the most terrains, and how
many fixed settings cross every terrain that switching crosses; and last, for each slope, the
neuron the switching table uses and the best fixed setting, each held on that constant slope. Runs are kept in ``--out``
(re-running resumes). About 10 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.planar_biped import PlanarBiped  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.acc import ACC  # noqa: E402
from sfl_brain.modules.controllers.reflex import ReflexController  # noqa: E402
from sfl_brain.recording.provenance import made_here  # noqa: E402
from sfl_brain.recording.records import read_records  # noqa: E402


def terrain(seed: int) -> str:
    rng = np.random.default_rng(seed)
    pieces, length = [(0.5, 0)], 0.5
    while length < 8.5:
        piece = round(float(rng.uniform(1.0, 2.5)), 1)
        pieces.append((piece, int(rng.integers(-10, 6))))
        length += piece
    return ",".join(f"{p:g}:{s}" for p, s in pieces)


def run(scenario: str, out: Path, *overrides: str) -> list[dict]:
    """``sfl run`` once (a completed run folder is kept), then its trial rows."""
    summary = out / "summary.json"
    if not (summary.exists() and json.loads(summary.read_text()).get("status") == "completed"):
        args = [sys.executable, "-m", "sfl_brain.cli", "run", str(ROOT / "scenarios" / scenario), "--out", str(out)]
        for o in overrides:
            args += ["--set", o]
        subprocess.run([*args, "--quiet"], check=True, cwd=ROOT)
    return [r for r in read_records(out) if r.get("kind") == "trial"]


def on_slope(alpha: float, theta: float, slope: float) -> str:
    """One E3.5 trial (15 s, 7.5 m to succeed) of a fixed setting on a constant slope."""
    body = PlanarBiped(PlanarBiped.Params(duration=15.0, min_distance=7.5))
    body.link = InProcessLink(ReflexController())
    request = TrialRequest(
        trial_id=0,
        seed=0,
        body_params={"slope_deg": slope},
        controller_params={"alpha_hip": alpha, "theta_hip_max_deg": theta},
        log=False,
    )
    result = body.handle(request)
    verdict = "walks" if result.success else "falls" if result.metrics["fell"] else "stalls"
    return f"{verdict} ({result.metrics['distance']:.1f} m)"


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--terrains", type=int, default=12)
    parser.add_argument("--maps", default="runs/chapter3/e3_4_s0/acc.npz", help="the E3.4 map to switch with")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "e3_5_terrains")
    parser.add_argument("--table", type=Path, default=ROOT / "docs" / "results" / "e3_5_terrains.md")
    args = parser.parse_args()
    maps = (ROOT / args.maps).resolve()
    profiles, switching, fixed, settings = [], [], [], None
    for k in range(1, args.terrains + 1):
        profile = terrain(k)
        condition = "conditions=" + json.dumps({"body.terrain": profile})
        exploit = run(
            "e3_5_terrain.yaml",
            args.out / f"t{k:02d}_switching_{maps.parent.name}",  # one per map; the sweeps are shared
            condition,
            f"protocol.maps={maps}",
            "protocol.trials=1",
            "record.body_every=0",
        )
        sweep = run("e3_5_fixed.yaml", args.out / f"t{k:02d}_fixed", condition)
        sweep.sort(key=lambda r: (r["alpha_hip"], r["theta_hip_max"]))
        here = [(round(r["alpha_hip"], 3), round(r["theta_hip_max"], 3)) for r in sweep]
        assert settings is None or here == settings, "the fixed grids differ between terrains"
        settings = here
        profiles.append(profile)
        switching.append(bool(exploit[0]["success"]))
        fixed.append([bool(r["success"]) for r in sweep])
        print(
            f"terrain {k:2d} {profile}: switching {'crossed' if switching[-1] else 'failed'} "
            f"({exploit[0]['m_distance']:.1f} m), fixed {sum(fixed[-1])}/{len(sweep)} crossed",
            flush=True,
        )
    fixed_a = np.array(fixed)  # terrains x settings
    switch_a = np.array(switching)
    per_setting = fixed_a.sum(axis=0)
    covers = fixed_a[switch_a].all(axis=0)  # crosses every terrain that switching crosses
    best = np.argsort(-per_setting, kind="stable")[:5]
    lines = [
        "# E3.5 over random terrains: switching against every fixed (alpha, theta)",
        "",
        made_here(),
        "",
        f"`python docs/experiments/e3_5_terrains.py --terrains {args.terrains} --maps {args.maps}` (rules in its "
        "docstring: pieces of 1-2.5 m, slopes -10..+5 deg, 7.5 m in 15 s to succeed; switching table from that "
        f"E3.4 map; fixed: the 21 x 21 grid of `e3_5_fixed.yaml`, {len(settings)} settings).",
        "",
        "| terrain | profile (m:deg) | switching | fixed settings that cross |",
        "|---|---|---|---|",
    ]
    for k, (profile, s, f) in enumerate(zip(profiles, switching, fixed, strict=True), start=1):
        lines.append(f"| {k} | `{profile}` | {'crossed' if s else 'failed'} | {sum(f)} ({100 * np.mean(f):.1f}%) |")
    lines += [
        "",
        f"- Switching crossed **{switch_a.sum()} of {len(switch_a)}** terrains.",
        "- The fixed settings that cross the most terrains: "
        + "; ".join(f"alpha {settings[i][0]:g} /rad, theta {settings[i][1]:g} deg: {per_setting[i]}" for i in best)
        + ".",
        f"- Fixed settings that cross every terrain switching crosses: **{int(covers.sum())} of {len(settings)}**"
        + (
            ": " + "; ".join(f"({settings[i][0]:g}, {settings[i][1]:g})" for i in np.flatnonzero(covers)[:10])
            if covers.any()
            else ""
        )
        + ".",
        f"- Terrains that some fixed setting crosses and switching does not: "
        f"{int((fixed_a.any(axis=1) & ~switch_a).sum())}.",
    ]
    # each slope's neuron (the thesis's rule: the success neuron whose slope weight is closest,
    # as the exploit protocol asks ACC) against the best fixed setting, on that slope held constant
    acc = ACC(ACC.Params(shape=(5, 5, 5), dim=3, restore=str(maps)))
    slopes = np.arange(-10, 6)
    table = acc.exploit(2, (slopes + 10) / 20)  # the scenario's axes: alpha 0-20, theta 90-150, slope -10..+10
    a0, t0 = settings[best[0]]
    lines += [
        "",
        f"Each slope's switching neuron, and the best fixed setting (alpha {a0:g}, theta {t0:g}), held on that "
        "slope for 15 s:",
        "",
        "| slope (deg) | neuron: alpha (/rad), theta (deg), its slope | the neuron | the best fixed setting |",
        "|---|---|---|---|",
    ]
    for slope, (wa, wt, ws) in zip(slopes, table, strict=True):
        alpha, theta = 20 * wa, 90 + 60 * wt
        lines.append(
            f"| {slope:+d} | {alpha:.1f}, {theta:.0f}, {-10 + 20 * ws:+.1f} | {on_slope(alpha, theta, slope)} "
            f"| {on_slope(a0, t0, slope)} |"
        )
    text = "\n".join(lines) + "\n"
    args.table.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
