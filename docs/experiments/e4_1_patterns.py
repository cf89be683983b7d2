"""E4.1: the motion patterns of one CPG joint over (sigma_s, sigma_f) (thesis Fig. 4.5), extensor / flexor
domination by theta_MLR (Fig. 4.6), and rhythm deletion without phase resetting (L1104, L1156).

    python docs/experiments/e4_1_patterns.py [--step 0.25] [--seconds 20] [--out docs/results/chapter4]

1. The pattern map: one joint (RG, PF, MN, extensor and flexor; no sensors) for every (sigma_s, sigma_f) of a
   grid over [0, 5]^2, all grid points as one batch of networks (one array update per RK4 stage), kicked with
   +1 into RG-F (-1 into RG-E) for 80 ms at t = 0 and run ``--seconds`` s; each point's flexor RG potential is
   classified (modules/cpg/patterns.py: plateau, quiescent, almost oscillator, oscillator with its frequency).
   Two maps: E and F uncoupled (each a lone Rowat-Selverston cell, what the digest's reference map of
   CPG-HUMANOID.md §1.7 simulated) and coupled by Table 4.1's RG-E <-> RG-F weight -1 (the thesis's joint).
   The uncoupled map is compared, cell by cell, with the rules the digest states.
2. Domination: an oscillating joint (sigma_s, sigma_f) = (2, 2), E and F coupled, with theta_MLR = +0.5, 0, -0.5,
   both ways the PF can read its RG (the circuit key ``pf_input``, issue 23): the potential V itself, and the
   bounded output tanh(V / A_f); each with the PF slopes the shipped circuits use now and used before issue 23, for
   a PF fed the RG alone (hip, knee: I = RG) and fed a fifth of it (the ankle pitch: I = RG / 5, (4.10) with its
   four contact and falling sensors silent).
3. Deletion: the planar circuit's left hip silenced by alpha_MLR = 0 from 4 s to 6 s, against an undisturbed run.
4. Energy order (Fig. 4.16, L1298): log10 of (4.15) of theta = MN_E - MN_F over the 10 s after the kick (§7.13),
   for every point of the uncoupled map, per class, both ways and with the PF slopes of the shipped circuits.

Writes e4_1_pattern_map.png, e4_1_domination.png, e4_1_deletion.png and e4_1_patterns.md into ``--out``, and
prints the Markdown. About a minute on 2 cores.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.stats import spearmanr  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.modules.cpg import CPGNetwork, load_circuit  # noqa: E402
from sfl_brain.modules.cpg.patterns import (  # noqa: E402
    ALMOST_OSCILLATOR,
    KICK_DURATION,
    OSCILLATOR,
    PLATEAU,
    QUIESCENT,
    classify,
    log_energy,
    simulate_one_joint,
)
from sfl_brain.recording.provenance import made_here  # noqa: E402

DT = 0.01
MARKER = {PLATEAU: "x", QUIESCENT: "*", ALMOST_OSCILLATOR: "+", OSCILLATOR: "o"}  # as Fig. 4.5
LETTER = {PLATEAU: "P", QUIESCENT: "Q", ALMOST_OSCILLATOR: "A", OSCILLATOR: "O"}


def pattern_map(grid: np.ndarray, seconds: float, rg_mutual: float) -> tuple[np.ndarray, np.ndarray, dict]:
    """Classes and frequencies over grid x grid, [sigma_s index, sigma_f index]."""
    sigma_s, sigma_f = np.meshgrid(grid, grid, indexing="ij")
    traces = simulate_one_joint(sigma_s.ravel(), sigma_f.ravel(), duration=seconds, rg_mutual=rg_mutual)
    patterns = [classify(traces["V_F"][:, n], DT, KICK_DURATION) for n in range(sigma_s.size)]
    kinds = np.array([p.kind for p in patterns]).reshape(sigma_s.shape)
    frequency = np.array([p.frequency for p in patterns]).reshape(sigma_s.shape)
    return kinds, frequency, traces


def reference_class(sigma_s: float, sigma_f: float) -> str | None:
    """The class the digest's §1.7 states for a grid point, None where it states nothing."""
    if sigma_f <= 0.25:
        return QUIESCENT
    if sigma_f == 0.5:
        return QUIESCENT if sigma_s <= 2.25 else ALMOST_OSCILLATOR
    if sigma_f <= 1.0:
        return ALMOST_OSCILLATOR if sigma_s > 0 else None  # "A for sigma_f in [0.5, 1.0] (above Q)"
    # "O for sigma_f >= 1.25 and sigma_s >~ (sigma_f - 1) / 2 (sigma_f = 2: sigma_s >= 0.75; 3: >= 1.25; 5: >= 2.25)":
    # its three explicit boundaries lie one step above the line, so strictly above it
    return OSCILLATOR if sigma_s > (sigma_f - 1) / 2 else PLATEAU


def draw_map(ax, grid, kinds, frequency, title):
    for kind, marker in MARKER.items():
        i, j = np.nonzero(kinds == kind)
        if kind == OSCILLATOR:
            sc = ax.scatter(grid[j], grid[i], c=frequency[i, j], marker="o", s=22, cmap="viridis", vmin=0, vmax=1.6)
        else:
            ax.scatter(grid[j], grid[i], marker=marker, s=30, color="k", label=kind.replace("_", " "))
    line = np.linspace(1.0, 5.0, 20)
    ax.plot(line, (line - 1) / 2, "r--", lw=1, label="digest: O above (sigma_f - 1) / 2")
    ax.set_xlabel("sigma_f")
    ax.set_ylabel("sigma_s")
    ax.set_title(title, fontsize=10)
    return sc


THETA_MLR = (0.5, 0.0, -0.5)  # Fig. 4.6, L1160: +0.5 extensor, -0.5 flexor domination
#: the PF slopes of the shipped circuits before issue 23, when their PF read V (``pf_input: potential``)
SLOPES_ON_V = {
    "planar_8link": {"hip_l": 1.0, "ankle_l": 5.0},
    "humanoid_nao": {"hip_pitch_l": 0.2, "ankle_pitch_l": 1.0},
}


def domination_cases() -> list[dict]:
    """The PF variants of the domination table: both inputs, each with the slopes of the planar circuit's hip and
    ankle and the humanoid's hip pitch and ankle pitch, now (read from the circuit files) and on V before issue 23."""
    cases = []
    for name, joints in SLOPES_ON_V.items():
        circuit = load_circuit(name)
        for joint, slope_on_v in joints.items():
            w_rg2pf = 0.2 if joint.startswith("ankle") else 1.0  # (n + 1) = 5 at the ankles (4.10)
            where = f"{name} {joint[:-2]}"
            now = circuit.joints[circuit.joint_index(joint)].pf.alpha
            cases.append({"input": "potential", "alpha": slope_on_v, "w_rg2pf": w_rg2pf, "where": where + " (before)"})
            cases.append({"input": circuit.pf_input, "alpha": now, "w_rg2pf": w_rg2pf, "where": where})
    return cases


def pf_label(case: dict) -> str:
    rg = "V" if case["input"] == "potential" else "tanh(V / 5)"
    return f"I = {rg}{' / 5' if case['w_rg2pf'] != 1.0 else ''}, slope {case['alpha']:g}"


def domination(seconds: float = 10.0) -> tuple[list[dict], dict]:
    """Each case of ``domination_cases`` at theta_MLR = +0.5, 0, -0.5 on the coupled joint (2, 2): the share of
    time MN_E leads, and the mean and range of MN_E - MN_F after a 4-s transient."""
    rows, traces = [], {}
    for case in domination_cases():
        out = simulate_one_joint(
            [2.0] * 3,
            [2.0] * 3,
            duration=seconds,
            rg_mutual=-1.0,
            theta_mlr=list(THETA_MLR),
            w_rg2pf=case["w_rg2pf"],
            pf_alpha=case["alpha"],
            pf_input=case["input"],
        )
        traces[(pf_label(case), case["where"])] = out
        late = slice(int(4.0 / DT), None)  # after the transient
        for n, theta_mlr in enumerate(THETA_MLR):
            e, f = out["MN_E"][late, n], out["MN_F"][late, n]
            rows.append(
                {
                    "pf": pf_label(case),
                    "where": case["where"],
                    "theta_mlr": theta_mlr,
                    "extensor_time": float(np.mean(e > f)),
                    "mean_angle": float(np.mean(e - f)),
                    "range": (float(np.min(e - f)), float(np.max(e - f))),
                }
            )
    return rows, traces


#: the energy order's PF variants: on V with slope 1 (the planar hip's before issue 23, and sfl report's) and with the
#: author's near-linear 0.02 (§5); on tanh(V / A_f) with the shipped planar hip's and humanoid hip pitch's slopes
def energy_cases() -> list[dict]:
    planar, humanoid = load_circuit("planar_8link"), load_circuit("humanoid_nao")
    slope = {c.name: c.joints[c.joint_index(j)].pf.alpha for c, j in ((planar, "hip_l"), (humanoid, "hip_pitch_l"))}
    return [
        {"input": "potential", "alpha": 1.0, "w_rg2pf": 1.0, "where": "planar hip before; sfl report"},
        {"input": "potential", "alpha": 0.02, "w_rg2pf": 1.0, "where": "the author's code (§5)"},
        {"input": planar.pf_input, "alpha": slope["planar_8link"], "w_rg2pf": 1.0, "where": "planar hip"},
        {"input": humanoid.pf_input, "alpha": slope["humanoid_nao"], "w_rg2pf": 1.0, "where": "humanoid hip pitch"},
    ]


def energy_order(grid: np.ndarray, kinds: np.ndarray, frequency: np.ndarray, seconds: float) -> list[dict]:
    """log10 (4.15) per point of the uncoupled map (the joint angle MN_E - MN_F, 10 s from the end of the kick, §7.13)
    for each of ``energy_cases``: per class its range, the pairs of neighbouring classes out of order, and the rank
    correlation of the oscillators' frequency with their energy."""
    sigma_s, sigma_f = np.meshgrid(grid, grid, indexing="ij")
    start, window = int(round(KICK_DURATION / DT)), int(round(10.0 / DT))
    order = (PLATEAU, QUIESCENT, ALMOST_OSCILLATOR, OSCILLATOR)
    flat_kinds, flat_frequency = kinds.ravel(), frequency.ravel()
    rows = []
    for case in energy_cases():
        traces = simulate_one_joint(
            sigma_s.ravel(),
            sigma_f.ravel(),
            duration=seconds,
            rg_mutual=0.0,
            pf_alpha=case["alpha"],
            pf_input=case["input"],
        )
        log_e = log_energy(traces["angle"][start : start + window + 1], DT)
        by_class = {k: log_e[flat_kinds == k] for k in order}
        crossed = [
            (int(np.sum(by_class[lo][:, None] > by_class[hi][None, :])), by_class[lo].size * by_class[hi].size)
            for lo, hi in zip(order, order[1:], strict=False)
        ]
        oscillating = flat_kinds == OSCILLATOR
        rho = float(spearmanr(flat_frequency[oscillating], log_e[oscillating])[0])
        rows.append({**case, "pf": pf_label(case), "by_class": by_class, "crossed": crossed, "rho": rho})
    return rows


def deletion() -> dict:
    circuit = load_circuit("planar_8link")
    hip = circuit.joint_index("hip_l")
    deleted, reference = CPGNetwork(circuit), CPGNetwork(circuit)
    record = {k: [] for k in ("t", "V_deleted", "V_reference", "angle_deleted", "angle_reference")}
    for tick in range(1000):
        if tick == 400:
            deleted.set_descending(alpha_mlr=0.0, joints=["hip_l"])
        if tick == 600:
            deleted.set_descending(alpha_mlr=1.0, joints=["hip_l"])
        deleted.advance()
        reference.advance()
        record["t"].append(deleted.time)
        record["V_deleted"].append(deleted.membrane_potential[hip, 1])
        record["V_reference"].append(reference.membrane_potential[hip, 1])
        record["angle_deleted"].append(deleted.command()[hip])
        record["angle_reference"].append(reference.command()[hip])
    out = {k: np.array(v) for k, v in record.items()}
    during = (out["t"] > 4.0) & (out["t"] <= 6.0)
    after = out["t"] > 6.0
    out["held_range"] = float(np.ptp(out["angle_deleted"][during]))
    out["after_difference"] = float(np.max(np.abs(out["angle_deleted"][after] - out["angle_reference"][after])))
    out["rg_difference"] = float(np.max(np.abs(out["V_deleted"] - out["V_reference"])))
    return out


def single_points(seconds: float) -> dict:
    """Periods and amplitudes the digest quotes, and the thesis's three eliminated failure neurons (sigma = 5 w)."""
    points = {
        "(sigma_s, sigma_f) = (1, 2)": (1.0, 2.0),
        "(2, 2)": (2.0, 2.0),
        "(3, 2)": (3.0, 2.0),
        "(5, 2)": (5.0, 2.0),
        "(17.5, 17.5), the author's walking pattern": (17.5, 17.5),
        "(5, 17.5)": (5.0, 17.5),
        "failure neuron (0.39, 0.57) x 5": (1.95, 2.85),
        "failure neuron (0.46, 0.33) x 5": (2.3, 1.65),
        "failure neuron (0.17, 0.23) x 5": (0.85, 1.15),
    }
    ss, sf = zip(*points.values(), strict=True)
    traces = simulate_one_joint(list(ss), list(sf), duration=seconds, rg_mutual=0.0)
    out = {}
    for n, name in enumerate(points):
        p = classify(traces["V_F"][:, n], DT, KICK_DURATION)
        tail = traces["V_F"][len(traces["time"]) // 2 :, n]
        out[name] = (p, float(tail.max()), float(tail.min()))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--step", type=float, default=0.25)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "results" / "chapter4")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    grid = np.round(np.arange(0.0, 5.0 + 1e-9, args.step), 6)

    maps = {}
    for name, mutual in (("uncoupled", 0.0), ("coupled", -1.0)):
        t = time.perf_counter()
        kinds, frequency, _ = pattern_map(grid, args.seconds, mutual)
        maps[name] = (kinds, frequency, time.perf_counter() - t)

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2), sharey=True)
    titles = {
        "uncoupled": "E and F uncoupled (a lone cell, the digest's §1.7 reference)",
        "coupled": "E <-> F coupled by -1 (Table 4.1, the thesis's joint)",
    }
    for ax, (name, (kinds, frequency, _)) in zip(axes, maps.items(), strict=True):
        sc = draw_map(ax, grid, kinds, frequency, titles[name])
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=9, bbox_to_anchor=(0.45, -0.04))
    fig.colorbar(sc, ax=axes, label="oscillation frequency (Hz)", shrink=0.8)
    fig.suptitle("E4.1: patterns of one joint after an 80-ms kick (Fig. 4.5): x plateau, * quiescent, + almost, o osc.")
    fig.savefig(args.out / "e4_1_pattern_map.png", dpi=110, bbox_inches="tight")
    plt.close(fig)

    # cell-by-cell against the digest's stated rules
    kinds = maps["uncoupled"][0]
    stated = agree = 0
    differ = []
    for i, s in enumerate(grid):
        for j, f in enumerate(grid):
            ref = reference_class(s, f)
            if ref is None:
                continue
            stated += 1
            if ref == kinds[i, j]:
                agree += 1
            else:
                differ.append(f"(sigma_s {s:g}, sigma_f {f:g}): ours {LETTER[kinds[i, j]]}, digest {LETTER[ref]}")
    counts = {name: {k: int(np.sum(m[0] == k)) for k in MARKER} for name, m in maps.items()}
    changed = int(np.sum(maps["uncoupled"][0] != maps["coupled"][0]))

    singles = single_points(args.seconds)
    dom_rows, dom_traces = domination()
    deleted = deletion()
    energies = energy_order(grid, *maps["uncoupled"][:2], args.seconds)

    # figures: domination and deletion
    shown = [key for key in dom_traces if key[1].startswith("planar_8link")]  # the planar hip and ankle, before and now
    fig, axes = plt.subplots(len(shown), 3, figsize=(14, 2.4 * len(shown)), sharex=True, sharey=True)
    for r, key in enumerate(shown):
        out = dom_traces[key]
        window = (out["time"] >= 4.0) & (out["time"] <= 8.0)
        for c, theta_mlr in enumerate(THETA_MLR):
            ax = axes[r, c]
            ax.plot(out["time"][window], out["MN_E"][window, c], label="MN_E")
            ax.plot(out["time"][window], out["MN_F"][window, c], label="MN_F")
            where = key[1].replace("planar_8link ", "planar ")
            ax.set_title(f"{where}: {key[0]}; theta_MLR {theta_mlr:+g}", fontsize=7.5)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("t (s)")
    fig.suptitle(
        "E4.1: extensor (+0.5) and flexor (-0.5) domination (Fig. 4.6), joint (2, 2): the PF fed V (before) "
        "and tanh(V / A_f) (now)"
    )
    fig.savefig(args.out / "e4_1_domination.png", dpi=110, bbox_inches="tight")
    plt.close(fig)

    fig, axes = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    axes[0].plot(deleted["t"], deleted["V_reference"], "k", lw=2.5, alpha=0.35, label="undisturbed")
    axes[0].plot(deleted["t"], deleted["V_deleted"], "C3", lw=1, label="alpha_MLR = 0 in [4, 6) s")
    axes[0].set_ylabel("RG-F V, left hip")
    axes[0].legend(fontsize=8, loc="upper right")
    axes[1].plot(deleted["t"], deleted["angle_reference"], "k", lw=2.5, alpha=0.35)
    axes[1].plot(deleted["t"], deleted["angle_deleted"], "C3", lw=1)
    axes[1].axvspan(4.0, 6.0, color="0.9")
    axes[1].set_ylabel("command (3.6), V")
    axes[1].set_xlabel("t (s)")
    fig.suptitle("E4.1: rhythm deletion without phase resetting (planar circuit, left hip)")
    fig.savefig(args.out / "e4_1_deletion.png", dpi=110, bbox_inches="tight")
    plt.close(fig)

    # the table
    lines = [
        "# E4.1: patterns of one joint (thesis Figs. 4.5, 4.6)",
        "",
        made_here(),
        "",
        f"`python docs/experiments/e4_1_patterns.py` ({args.step:g} grid over [0, 5]^2, {args.seconds:g} s per"
        f" point, kick +1 / -1 for 80 ms; {time.perf_counter() - started:.0f} s in all).",
        "",
        "## Pattern map",
        "",
        "| map | plateau | quiescent | almost osc. | oscillator | batch of networks, wall time |",
        "|---|---|---|---|---|---|",
    ]
    for name, (_, _, wall) in maps.items():
        c = counts[name]
        lines.append(
            f"| {name} | {c[PLATEAU]} | {c[QUIESCENT]} | {c[ALMOST_OSCILLATOR]} | {c[OSCILLATOR]} "
            f"| {grid.size**2} joints, {wall:.1f} s |"
        )
    lines += [
        "",
        f"Coupling E and F by Table 4.1's -1 changes the class of {changed} of {grid.size**2} points.",
        "",
        f"Uncoupled map against the digest's stated rules (§1.7), where they state a class: **{agree} of {stated}**"
        f" points agree ({100 * agree / stated:.0f}%).",
        "",
        "Points that differ: " + ("; ".join(differ) if differ else "none") + ".",
        "",
        "## Single points (uncoupled cell)",
        "",
        "| point | digest (§1.7) | ours | V range |",
        "|---|---|---|---|",
    ]
    expected = {
        "(sigma_s, sigma_f) = (1, 2)": "O, 2.25 s, +-5.5",
        "(2, 2)": "O, 1.25 s",
        "(3, 2)": "O, 0.95 s",
        "(5, 2)": "O, 0.69 s",
        "(17.5, 17.5), the author's walking pattern": "O, 0.394 s, +-6.16",
        "(5, 17.5)": "P",
        "failure neuron (0.39, 0.57) x 5": "O",
        "failure neuron (0.46, 0.33) x 5": "O",
        "failure neuron (0.17, 0.23) x 5": "O",
    }
    for name, (p, vmax, vmin) in singles.items():
        ours = LETTER[p.kind] + (f", {1 / p.frequency:.3f} s" if p.kind == OSCILLATOR else "")
        lines.append(f"| {name} | {expected[name]} | {ours} | [{vmin:.2f}, {vmax:.2f}] |")
    lines += [
        "",
        "## Domination (Fig. 4.6): oscillating joint (2, 2), E and F coupled by -1",
        "",
        "theta_MLR enters the PF threshold with opposite signs on E and F (§7.6). The PF reads its RG as V itself",
        "(`pf_input: potential`, both circuits before issue 23) or as tanh(V / A_f) (`pf_input: bounded`, the circuits",
        "now); the slopes are those of the circuit and joint named. Time with MN_E > MN_F after a 4-s transient, at",
        "theta_MLR = +0.5 / 0 / -0.5, then the mean and range of MN_E - MN_F.",
        "",
        "| PF input (4.10), slope | used by | MN_E ahead, +0.5 / 0 / -0.5 | mean MN_E - MN_F, +0.5 / 0 / -0.5 "
        "| range at +0.5 | range at -0.5 |",
        "|---|---|---|---|---|---|",
    ]
    for k in range(0, len(dom_rows), len(THETA_MLR)):
        group = dom_rows[k : k + len(THETA_MLR)]
        (lo_e, hi_e), (lo_f, hi_f) = group[0]["range"], group[-1]["range"]
        lines.append(
            f"| {group[0]['pf']} | {group[0]['where']} | "
            + " / ".join(f"{100 * r['extensor_time']:.0f}%" for r in group)
            + " | "
            + " / ".join(f"{r['mean_angle']:+.3f}" for r in group)
            + f" | [{lo_e:+.3f}, {hi_e:+.3f}] | [{lo_f:+.3f}, {hi_f:+.3f}] |"
        )
    share = {(r["where"], r["theta_mlr"]): 100 * r["extensor_time"] for r in dom_rows}

    def spread(where: str) -> str:
        return f"{share[(where, 0.5)]:.0f}% / {share[(where, -0.5)]:.0f}%"

    lines += [
        "",
        f"- **Fed V, theta_MLR = +-0.5 hardly dominates** a hip: MN_E ahead {spread('planar_8link hip (before)')} of "
        f"the time (the planar hip's slope 1; the humanoid's 0.2: {spread('humanoid_nao hip_pitch (before)')}). V "
        "swings +-5.5 with fast jumps, so a threshold moved by 0.5 changes the duty cycle by a few per cent.",
        f"- **Fed tanh(V / A_f), it dominates as Fig. 4.6**: {spread('planar_8link hip')} (planar hip), "
        f"{spread('humanoid_nao hip_pitch')} (humanoid hip pitch), and the joint keeps oscillating (the ranges).",
        f"- **At the ankles the bounded input deletes the rhythm instead**: {spread('planar_8link ankle')}. Their "
        "(n + 1) = 5 averaging leaves an input of +-0.16, smaller than the 0.5 threshold shift, so one motor neuron "
        "stays on for the whole cycle. Fed V, the ankle's input (+-1.1) was of the right size: "
        f"{spread('planar_8link ankle (before)')}.",
    ]
    lines += [
        "",
        "## Energy order (Fig. 4.16, L1298): every point of the uncoupled map",
        "",
        "log10 of (4.15) on theta = MN_E - MN_F over the 10 s after the kick (§7.13), the classes of the uncoupled map",
        'above. "Out of order": pairs of points of two neighbouring classes whose energies are in the wrong order.',
        "rho: the rank correlation of the oscillators' frequency with their energy.",
        "",
        "| PF input, slope | used by | log10 E: P | Q | A | O | out of order: P > Q, Q > A, A > O | rho |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in energies:
        ranges = " | ".join(
            f"{row['by_class'][k].min():.2f} to {row['by_class'][k].max():.2f}"
            for k in (PLATEAU, QUIESCENT, ALMOST_OSCILLATOR, OSCILLATOR)
        )
        crossed = ", ".join(f"{100 * n / total:.1f}%" for n, total in row["crossed"])
        lines.append(f"| {row['pf']} | {row['where']} | {ranges} | {crossed} | {row['rho']:+.2f} |")

    def worst(row: dict) -> float:
        return max(100 * n / total for n, total in row["crossed"])

    bounded = [row for row in energies if row["input"] == "bounded"]
    plateau_above = 100 * energies[1]["crossed"][0][0] / energies[1]["crossed"][0][1]
    lines += [
        "",
        "- The order P < Q < A < O holds on tanh(V / A_f) as it did on V with slope 1: at most "
        + ", ".join(f"{worst(row):.1f}%" for row in bounded)
        + " of the pairs of neighbouring classes out of order (the slopes "
        + ", ".join(f"{row['alpha']:g}" for row in bounded)
        + f"; on V, slope 1: {worst(energies[0]):.1f}%), almost all of them quiescent points above the least "
        "active almost-oscillators, at the Q / A border. The oscillators' energy rises with their frequency "
        "(rho " + ", ".join(f"{row['rho']:+.2f}" for row in bounded) + f"; on V {energies[0]['rho']:+.2f}).",
        f"- The author's near-linear slope 0.02 on V breaks it: {plateau_above:.0f}% of the plateau-quiescent pairs "
        "are out of order (a plateau's slow drift "
        "then counts for more than a quiescent cell's return to rest).",
    ]
    lines += [
        "",
        "## Rhythm deletion (planar circuit, left hip, alpha_MLR = 0 from 4 s to 6 s)",
        "",
        f"- command range while deleted: {deleted['held_range']:.3g} V (held still);",
        f"- largest RG difference from the undisturbed run: {deleted['rg_difference']:.3g} (the RG never stops);",
        f"- largest command difference after 6 s: {deleted['after_difference']:.3g} V (the old phase, no reset).",
        "",
        "![](e4_1_pattern_map.png)",
        "",
        "![](e4_1_domination.png)",
        "",
        "![](e4_1_deletion.png)",
        "",
    ]
    text = "\n".join(lines)
    (args.out / "e4_1_patterns.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
