"""Chapter-4 figures and tables of ``sfl report``, for runs whose controller is the CPG (E4.2).

For each run:

* the success and failure maps over (sigma_s, sigma_f) (Fig. 4.13), each neuron marked by the pattern of one joint
  with its (sigma_s, sigma_f) (Fig. 4.5's markers: x plateau, * quiescent, + almost an oscillator, o oscillator);
  the failure neurons pruned after the run (L1255) hollow;
* the energy ordering of the map neurons (Fig. 4.16, L1298): log10 of (4.15) per neuron, sorted, coloured by class,
  with a check of the thesis's order plateau < quiescent < almost-oscillator < oscillators by frequency;
* the success rate over the trials, with the scheduled vigilance band (4.14) (Fig. 4.13(c));
* a gait strip: the walker's stick figure every half second, from one trial re-simulated in this process with the
  run's scenario at the point of its best successful trial (the walker is deterministic; the re-simulated steps and
  distance are compared with the recorded ones and both are printed).

A neuron's pattern and energy come from one joint (RG, PF, MN, E and F; ``modules/cpg/patterns.py``), kicked as
the digest's reference map (+1 into RG-F for 80 ms) and run 20 s: the class from the flexor RG's potential, the
energy from theta = MN_E - MN_F over 10 s from the end of the kick (digest §7.13). E and F are uncoupled, the single
cell of the digest's reference map (§1.7) that E4.1 and the energy test of tests/modules/test_cpg.py use; the classes of
the coupled joint (Table 4.1's -1) are counted beside them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

#: the joint's patterns, in the thesis's energy order (Fig. 4.16, L1298)
KINDS = ("plateau", "quiescent", "almost_oscillator", "oscillator")
LETTER = {"plateau": "P", "quiescent": "Q", "almost_oscillator": "A", "oscillator": "O"}
MARKER = {"plateau": "x", "quiescent": "*", "almost_oscillator": "P", "oscillator": "o"}  # as Fig. 4.5
COLOUR = {"plateau": "tab:brown", "quiescent": "tab:grey", "almost_oscillator": "tab:orange", "oscillator": "tab:blue"}
DT = 0.01  # s, the one-joint simulation's control tick
SECONDS = 20.0  # s, each neuron's one-joint run (as E4.1)
GAIT_EVERY = 0.5  # s between two stick figures of the gait strip

#: the thesis's E4.2 (§4.4.3, L1255-1260, Fig. 4.13, Fig. 4.16 L1298)
THESIS = {
    "pruned": 3,
    "failure classes": {"plateau": 2, "quiescent": 16, "almost_oscillator": 4, "oscillator": 0},
    "success classes": {"oscillator": 25},
}


def is_cpg_run(scenario: dict) -> bool:
    """A chapter-4 learning run: the CPG (or the 8-link walker) learning over sigma_s and sigma_f. Other CPG runs
    (a sweep of the humanoid over alpha_MLR) keep the generic figure."""
    modules = scenario.get("modules", {})
    cpg = modules.get("controller", {}).get("impl") == "cpg" or modules.get("body", {}).get("impl") == "planar_8link"
    axes = {a.get("name") for a in scenario.get("space", [])}
    return cpg and scenario.get("protocol", {}).get("kind") == "learn" and {"sigma_s", "sigma_f"} <= axes


@dataclass(frozen=True)
class Neuron:
    """One map neuron: its map, index, whether it survived the pruning, its wins, its (sigma_s, sigma_f), and the
    pattern and log10 energy (4.15) of one joint at that point."""

    map: str
    index: int
    active: bool
    wins: int
    sigma_s: float
    sigma_f: float
    kind: str
    frequency: float
    log_energy: float
    kind_coupled: str


def joint_patterns(sigma_s, sigma_f, rg_mutual: float = 0.0, seconds: float = SECONDS):
    """Class, frequency (Hz, NaN unless an oscillator) and log10 energy (4.15) of one joint per (sigma_s, sigma_f)
    pair, all pairs as one batch of networks."""
    from ..modules.cpg.patterns import KICK_DURATION, classify, log_energy, simulate_one_joint

    traces = simulate_one_joint(sigma_s, sigma_f, duration=seconds, rg_mutual=rg_mutual, control_dt=DT)
    patterns = [classify(traces["V_F"][:, n], DT, KICK_DURATION) for n in range(traces["V_F"].shape[1])]
    start = int(round(KICK_DURATION / DT))
    window = int(round(10.0 / DT))  # 10 s from the end of the kick (§7.13)
    log_e = log_energy(traces["angle"][start : start + window + 1], DT)
    return [p.kind for p in patterns], np.array([p.frequency for p in patterns]), np.asarray(log_e)


def _axis(scenario: dict, name: str) -> dict:
    return next(a for a in scenario["space"] if a["name"] == name)


def map_neurons(run_dir: Path, scenario: dict) -> list[Neuron]:
    """Every neuron of both maps (``acc.npz``), failure map first (as Fig. 4.16), in physical units."""
    names = [a["name"] for a in scenario["space"]]
    ks, kf = names.index("sigma_s"), names.index("sigma_f")
    axes = _axis(scenario, "sigma_s"), _axis(scenario, "sigma_f")
    rows = []
    with np.load(run_dir / "acc.npz") as data:
        for which in ("failure", "success"):
            w = data[f"{which}_weights"]
            for n in range(len(w)):
                ss, sf = (
                    a["low"] + (a["high"] - a["low"]) * float(w[n, k]) for a, k in zip(axes, (ks, kf), strict=True)
                )
                rows.append((which, n, bool(data[f"{which}_active"][n]), int(data[f"{which}_wins"][n]), ss, sf))
    ss, sf = [r[4] for r in rows], [r[5] for r in rows]
    kinds, freq, log_e = joint_patterns(ss, sf)
    coupled, _, _ = joint_patterns(ss, sf, rg_mutual=-1.0)
    return [
        Neuron(*r, kind=k, frequency=float(f), log_energy=float(e), kind_coupled=c)
        for r, k, f, e, c in zip(rows, kinds, freq, log_e, coupled, strict=True)
    ]


def energy_order(neurons: list[Neuron]) -> dict:
    """Check the thesis's order on log E (Fig. 4.16, L1298): plateau < quiescent < almost-oscillator < oscillators,
    the oscillators by frequency. Returns the log E range of each class present, the class pairs that overlap (a
    lower class's highest above a higher class's lowest), and among the oscillators the pairs whose energy order
    contradicts their frequency order (discordant) and Spearman's rank correlation of frequency and log E."""
    ranges = {}
    for kind in KINDS:
        values = [n.log_energy for n in neurons if n.kind == kind]
        if values:
            ranges[kind] = (min(values), max(values), len(values))
    present = [k for k in KINDS if k in ranges]
    overlaps = [
        f"{LETTER[lo]} up to {ranges[lo][1]:.2f} > {LETTER[hi]} from {ranges[hi][0]:.2f}"
        for i, lo in enumerate(present)
        for hi in present[i + 1 :]
        if ranges[lo][1] >= ranges[hi][0]
    ]
    osc = sorted((n.frequency, n.log_energy) for n in neurons if n.kind == "oscillator")
    f, e = np.array([o[0] for o in osc]), np.array([o[1] for o in osc])
    pairs = discordant = 0
    for i in range(len(osc)):
        for j in range(i + 1, len(osc)):
            if f[i] != f[j]:
                pairs += 1
                discordant += int((e[j] - e[i]) * (f[j] - f[i]) < 0)
    rho = float(np.corrcoef(np.argsort(np.argsort(f)), np.argsort(np.argsort(e)))[0, 1]) if len(osc) > 2 else None
    return {
        "ranges": ranges,
        "class_order_holds": not overlaps,
        "overlaps": overlaps,
        "oscillator_pairs": pairs,
        "oscillator_discordant": discordant,
        "oscillator_spearman": rho,
    }


def _trial_rows(run_dir: Path) -> list[dict]:
    """The run's trial rows only (the decisions, hundreds of thousands, are skipped unparsed)."""
    rows = []
    with open(run_dir / "records.jsonl", "rb") as f:
        for line in f:
            if line.startswith(b'{"kind":"trial"'):
                try:
                    rows.append(json.loads(line))
                except ValueError:  # a torn last line
                    break
    return rows


def simulate_gait(scenario: dict, sigma_s: float, sigma_f: float) -> tuple[dict, np.ndarray, np.ndarray]:
    """Re-simulate one trial of the run's body and controller in this process at (sigma_s, sigma_f): its metrics,
    the picture times (s) and the stick figures, (frames, strips, points, 2) in m."""
    from ..body import InProcessLink
    from ..messages import TrialRequest
    from ..registry import resolve
    from ..telemetry import CaptureTelemetry, Rates, Strips2D

    modules = scenario["modules"]
    body_cls, _ = resolve(modules["body"]["impl"])
    ctrl_cls, _ = resolve(modules["controller"]["impl"])
    body = body_cls(body_cls.Params(**modules["body"].get("params", {})))
    body.link = InProcessLink(ctrl_cls(ctrl_cls.Params(**modules["controller"].get("params", {}))))
    body.telemetry = CaptureTelemetry(rates=Rates(signals_hz=1.0 / GAIT_EVERY, pictures_hz=1.0 / GAIT_EVERY))
    physical = {"body": {}, "controller": {}}
    for key, value in scenario.get("conditions", {}).items():
        owner, _, param = key.partition(".")
        physical[owner][param] = value
    physical["controller"].update(sigma_s=float(sigma_s), sigma_f=float(sigma_f))
    request = TrialRequest(
        trial_id=0,
        seed=int(scenario.get("seed", 0)),
        body_params=physical["body"],
        controller_params=physical["controller"],
        log=True,
    )
    result = body.handle(request)
    walker = next(i for i in body.telemetry.items if isinstance(i, Strips2D) and i.path == "walker")
    strips = np.array(walker.strips).reshape(len(walker.times), walker.per_frame, -1, 2)
    return result.metrics, np.asarray(walker.times), strips


def _draw_maps(ax, neurons: list[Neuron], scenario: dict) -> None:
    for which, edge in (("failure", "tab:red"), ("success", "tab:green")):
        for kind in KINDS:
            group = [n for n in neurons if n.map == which and n.kind == kind]
            for active in (True, False):
                sub = [n for n in group if n.active == active]
                if not sub:
                    continue
                hollow = not active and MARKER[kind] != "x"  # a pruned neuron: hollow (an x: light)
                ax.scatter(
                    [n.sigma_s for n in sub],
                    [n.sigma_f for n in sub],
                    s=60 if active else 110,
                    marker=MARKER[kind],
                    c="none" if hollow else (edge if active else "pink"),
                    edgecolors=edge if MARKER[kind] != "x" else None,
                    linewidths=1.2,
                    alpha=0.85,
                    label=f"{which}: {kind.replace('_', ' ')}" + ("" if active else " (pruned)"),
                )
    ss, sf = _axis(scenario, "sigma_s"), _axis(scenario, "sigma_f")
    line = np.linspace(1.0, sf["high"], 20)
    ax.plot((line - 1) / 2, line, "k:", lw=1, label="sigma_s = (sigma_f - 1) / 2 (digest)")
    ax.set_xlim(ss["low"], ss["high"])
    ax.set_ylim(sf["low"], sf["high"])
    ax.set_xlabel("sigma_s")
    ax.set_ylabel("sigma_f")


def _figures(run_dir: Path, out: Path, scenario: dict, neurons: list[Neuron], trials: list[dict], gait) -> list[str]:
    name = run_dir.name
    files = []
    # maps (Fig. 4.13) with trials behind them
    fig, ax = plt.subplots(figsize=(6.2, 5.2))
    tried = [(r["sigma_s"], r["sigma_f"], bool(r["success"])) for r in trials if r.get("sigma_s") is not None]
    if tried:
        t = np.array(tried, dtype=float)
        ok = t[:, 2] > 0.5
        ax.scatter(t[ok, 0], t[ok, 1], s=6, c="#b9e4c2", label="success trials")
        ax.scatter(t[~ok, 0], t[~ok, 1], s=6, c="#f4c0c0", label="failure trials")
    _draw_maps(ax, neurons, scenario)
    pruned = sum(1 for n in neurons if not n.active)
    ax.set_title(f"{name}: success (green) and failure (red) maps, {pruned} failure neurons pruned", fontsize=9)
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.savefig(out / f"{name}_maps.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    files.append(f"{name}_maps.png")
    # energy ordering (Fig. 4.16)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), sharey=True)
    kept = [n for n in neurons if n.active]
    for ax, order, title in (
        (axes[0], kept, "as Fig. 4.16: failure map first, then success map"),
        (axes[1], sorted(kept, key=lambda n: n.log_energy), "sorted by log E"),
    ):
        for kind in KINDS:
            xs = [i + 1 for i, n in enumerate(order) if n.kind == kind]
            ys = [n.log_energy for n in order if n.kind == kind]
            if xs:
                ax.scatter(xs, ys, marker=MARKER[kind], c=COLOUR[kind], s=40, label=kind.replace("_", " "))
        fails = [i + 1 for i, n in enumerate(order) if n.map == "failure"]
        ax.scatter(
            fails, [order[i - 1].log_energy for i in fails], s=120, facecolors="none", edgecolors="tab:red", lw=0.6
        )
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("neuron (red ring: failure map)")
    for i, n in enumerate(sorted(kept, key=lambda n: n.log_energy)):
        if n.kind == "oscillator":
            axes[1].annotate(
                f"{n.frequency:.2f}",
                (i + 1, n.log_energy),
                fontsize=5,
                rotation=90,
                xytext=(0, 6),
                textcoords="offset points",
                ha="center",
            )
    axes[0].set_ylabel("log10 E, (4.15) over 10 s")
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{name}: energy metric of the {len(kept)} map neurons after pruning (oscillators: frequency, Hz)")
    fig.savefig(out / f"{name}_energy.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    files.append(f"{name}_energy.png")
    # success rate over trials, with the vigilance band
    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    k = np.array([r["trial"] for r in trials])
    ok = np.array([bool(r["success"]) for r in trials], dtype=float)
    ax.plot(k + 1, np.cumsum(ok) / np.arange(1, len(ok) + 1), c="k", label="success rate so far")
    if len(ok) >= 20:
        window = np.convolve(ok, np.ones(20) / 20, mode="valid")
        ax.plot(np.arange(20, len(ok) + 1), window, c="tab:green", lw=1, label="last 20 trials")
    vig = [(r["trial"] + 1, r.get("band_low"), r.get("band_high"), r.get("s_vig")) for r in trials]
    vig = [v for v in vig if v[1] is not None]
    if vig:
        v = np.array(vig, dtype=float)
        ax.fill_between(v[:, 0], v[:, 1], v[:, 2], color="tab:purple", alpha=0.15, label="vigilance band (4.14)")
        ax.plot(v[:, 0], v[:, 3], ".", ms=2, c="tab:purple", label="s_vig drawn")
    ax.set_xlabel("trial")
    ax.set_ylim(-0.8, 1.02)
    ax.axhline(0, c="0.8", lw=0.5)
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(f"{name}: success rate over trials", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / f"{name}_learning.png", dpi=110)
    plt.close(fig)
    files.append(f"{name}_learning.png")
    if gait is not None:
        metrics, times, strips, point = gait
        fig, ax = plt.subplots(figsize=(12, 2.8))
        cmap = plt.get_cmap("viridis")
        for f in range(len(times)):
            colour = cmap(f / max(1, len(times) - 1))
            for strip in strips[f]:
                ax.plot(strip[:, 0], strip[:, 1], c=colour, lw=1)
        x = strips[..., 0]
        ax.axhline(0, c="k", lw=0.8)
        ax.set_xlim(x.min() - 0.1, x.max() + 0.1)
        ax.set_aspect("equal")
        ax.set_xlabel("x, m")
        ax.set_title(
            f"{name}: gait at (sigma_s, sigma_f) = ({point[0]:.2f}, {point[1]:.2f}), every {GAIT_EVERY:g} s "
            f"(dark to light); re-simulated: {metrics['steps']} steps, {metrics['distance']:.2f} m"
            + (f", fell at {metrics['fell_at']:.1f} s" if metrics["fell"] else ", no fall"),
            fontsize=9,
        )
        fig.savefig(out / f"{name}_gait.png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        files.append(f"{name}_gait.png")
    return files


def _counts(neurons: list[Neuron], which: str, attr: str = "kind") -> str:
    group = [n for n in neurons if n.map == which and n.active]
    return " ".join(f"{sum(1 for n in group if getattr(n, attr) == k)}{LETTER[k]}" for k in KINDS)


def cpg_run(run_dir: Path, out: Path, scenario: dict, status: str, gait: bool = True) -> dict:
    """Figures and numbers of one chapter-4 run."""
    trials = _trial_rows(run_dir)
    if not (run_dir / "acc.npz").exists():
        return {
            "run": run_dir.name,
            "scenario": scenario["name"],
            "status": status,
            "trials": len(trials),
            "figures": [],
        }
    neurons = map_neurons(run_dir, scenario)
    order = energy_order([n for n in neurons if n.active])
    order["success_map"] = energy_order([n for n in neurons if n.map == "success"])
    picked = None
    wins = [r for r in trials if r["success"] and r.get("sigma_s") is not None]
    if gait and wins and scenario["modules"].get("body", {}).get("impl") == "planar_8link":  # its stick figures
        best = max(wins, key=lambda r: r["quality"])
        metrics, times, strips = simulate_gait(scenario, best["sigma_s"], best["sigma_f"])
        picked = (metrics, times, strips, (best["sigma_s"], best["sigma_f"]))
        recorded = {"steps": best["m_steps"], "distance": best["m_distance"], "trial": best["trial"]}
    figures = _figures(run_dir, out, scenario, neurons, trials, picked)
    successes = sum(1 for r in trials if r["success"])
    summary = {}
    if (run_dir / "summary.json").exists():
        summary = json.loads((run_dir / "summary.json").read_text())
    return {
        "run": run_dir.name,
        "scenario": scenario["name"],
        "status": status,
        "seed": scenario.get("seed"),
        "trials": len(trials),
        "successes": successes,
        "failures": len(trials) - successes,
        "wall_time_s": summary.get("wall_time_s"),
        "pruned": [(n.index, n.sigma_s, n.sigma_f, n.kind) for n in neurons if not n.active],
        "failure_classes": _counts(neurons, "failure"),
        "success_classes": _counts(neurons, "success"),
        "failure_classes_coupled": _counts(neurons, "failure", "kind_coupled"),
        "success_classes_coupled": _counts(neurons, "success", "kind_coupled"),
        "order": order,
        "neurons": neurons,
        "gait": None if picked is None else {"recorded": recorded, "resimulated": picked[0], "point": picked[3]},
        "figures": figures,
    }


def _pct(part: int, whole: int) -> str:
    return f"{part / whole:.1%}" if whole else "-"


def write_cpg_sections(results: list[dict]) -> list[str]:
    """The Markdown of the chapter-4 runs: the over-seeds table, the energy order, the pruned neurons, the figures."""
    lines = [
        "",
        "## E4.2: learnt maps over (sigma_s, sigma_f), one run per seed",
        "",
        "Classes of the map neurons after pruning (one joint at the neuron's (sigma_s, sigma_f), E and F uncoupled;"
        " P plateau, Q quiescent, A almost an oscillator, O oscillator).",
        "",
        "| run | seed | status | trials | success rate | failures | both >= 20 % | pruned failure neurons "
        "| failure map | success map | class order on log E | oscillators: frequency vs log E | wall |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        if "order" not in r:
            lines.append(f"| {r['run']} | - | **{r['status']}** | {r['trials']} | no maps | | | | | | | | |")
            continue
        n = r["trials"]
        both = n and min(r["successes"], r["failures"]) >= 0.2 * n
        order = r["order"]
        held = "holds" if order["class_order_holds"] else "breaks: " + "; ".join(order["overlaps"])
        osc = "; ".join(
            f"{what}: Spearman {o['oscillator_spearman']:+.2f}, {o['oscillator_discordant']} of "
            f"{o['oscillator_pairs']} pairs discordant"
            for what, o in (("all", order), ("success map", order["success_map"]))
            if o["oscillator_spearman"] is not None
        )
        pruned = ", ".join(f"#{i} ({s:.2f}, {f:.2f}) {LETTER[k]}" for i, s, f, k in r["pruned"]) or "none"
        wall = f"{r['wall_time_s']:.0f} s" if r.get("wall_time_s") else "-"
        status = r["status"] if r["status"] == "completed" else f"**{r['status']}**"
        lines.append(
            f"| {r['run']} | {r['seed']} | {status} | {n} | {_pct(r['successes'], n)} | {_pct(r['failures'], n)} "
            f"| {'yes' if both else '**no**'} | {len(r['pruned'])}: {pruned} | {r['failure_classes']} "
            f"| {r['success_classes']} | {held} | {osc} | {wall} |"
        )
    lines += [
        "",
        "The same neurons classified on the coupled joint (RG-E <-> RG-F -1, Table 4.1):",
        "",
        "| run | failure map | success map |",
        "|---|---|---|",
    ]
    lines += [
        f"| {r['run']} | {r['failure_classes_coupled']} | {r['success_classes_coupled']} |"
        for r in results
        if "order" in r
    ]
    lines += ["", "log10 E of each class after pruning (min to max, count):", ""]
    lines += ["| run | " + " | ".join(LETTER[k] for k in KINDS) + " |", "|---|---|---|---|---|"]
    for r in results:
        if "order" in r:
            ranges = r["order"]["ranges"]
            cells = [
                f"{ranges[k][0]:.2f} to {ranges[k][1]:.2f} ({ranges[k][2]})" if k in ranges else "-" for k in KINDS
            ]
            lines.append(f"| {r['run']} | " + " | ".join(cells) + " |")
    for r in results:
        if not r["figures"]:
            continue
        lines += ["", f"### {r['run']}", ""]
        if r.get("gait"):
            g = r["gait"]
            rec, sim = g["recorded"], g["resimulated"]
            lines += [
                f"Gait: trial {rec['trial']} (the best successful one), re-simulated in-process: "
                f"{sim['steps']} steps, {sim['distance']:.3f} m (recorded: {rec['steps']} steps, "
                f"{rec['distance']:.3f} m).",
                "",
            ]
        lines += [f"![]({f})" for f in r["figures"]]
    return lines
