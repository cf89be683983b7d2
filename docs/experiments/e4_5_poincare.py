"""E4.5 (L1401-1413): the stability of the humanoid's CPG gait, by a Poincaré return map of the torso's pitch.

    python docs/experiments/e4_5_poincare.py [--duration 250] [--seeds 0 1 2] [--noise 0.02 0.05 0.1]
                                             [--smooth 0] [--figure docs/results/chapter4/e4_5_cobweb.png]
                                             [--save runs.npz | --load runs.npz]

The thesis walks NAO 250 s (400 steps), draws the phase diagram of the torso's inclination to the vertical, takes
the section Sigma "in one direction with null velocity" (crossings of pitch rate = 0 of one sign), and shows the first
returns r_0..r_3 approaching a fixed point r* = 0.046 where the cobweb meets the diagonal, "globally stable" (L1408).

Here the default gait of ``modules/cpg/circuits/humanoid_nao.yaml`` walks the body (``bodies/humanoid.py``) for
``--duration`` s on a long flat ground: the body's finish line set far away (1000 m) so that the trial does not end at
1.5 m, the ground extended (``run_out``, ``run_up``, ``ground_width``) and the lane widened to match, so the walk ends
only by a fall or the time-out. Each walk is one (seed, start_noise) pair: the seed draws the start's joint offsets, of
s.d. ``start_noise`` rad (the initial perturbation). Every control tick (10 ms) the script reads the torso's pitch
(``torso_pitch``: its angle to the vertical in its sagittal plane, + = forward) and its gyro rate about its own y axis.

The section (choices not in the thesis, §0.8): Sigma = the ticks where the gyro rate goes from + to - (the pitch's
maxima: the torso's most forward lean of each step), the return r_n = the pitch there (linearly interpolated between
the two ticks). ``--smooth W`` first smooths both by a centred moving average of W s (e.g. ``SMOOTH``, a third of the
gait cycle), a precaution against impact spikes that these walks do not need: the gyro's power is 95 % at 2-4 Hz,
and the raw and smoothed rates cross Sigma as often (756-759 and 753-755 times in 250 s); smoothing lowers the
maxima (r* by 0.03 rad). The map is fitted as r_{n+1} = a + b r_n by least squares over all returns of a walk: the
fixed point r* = a / (1 - b), the slope b (stable if |b| < 1), with the steady state's mean and s.d. of r_n (after
the first 10 s). The orbit crosses Sigma once per step, twice per gait cycle: the stride maps (every second return,
the two branches) are the return maps of the cycle. The figure: the first walk's phase diagram, every walk's step-map
cobweb of its first returns with the fitted map, and every walk's path seen from above.

Prints Markdown tables (per walk: how it ended, where, heading, when it would have left the default lane, returns;
r_0..r_3, the steady state, r* and b of each map) and writes the figure. About 11 s of wall time per 250-s walk on a
quiet core (33 s at load average 5-9).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.humanoid import Humanoid  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402

SMOOTH = 0.222  # s: an optional moving-average window (--smooth), a third of the 0.667-s gait cycle
SETTLE = 10.0  # s: returns after this are the steady state
DEFAULT_LANE = 0.5  # m: the body's default lane_half_width, for when the walk would have left it
#: a long flat walk (bodies/humanoid.py, docs/bodies/humanoid.md "Long walks"): no finish line within reach, 200 m
#: of ground ahead and 100 m behind, 400 m wide, the lane as wide as the ground
LONG_WALK = {"finish_line": 1000.0, "run_out": 200.0, "run_up": 100.0, "ground_width": 400.0, "lane_half_width": 199.0}


@dataclass
class Walk:
    """One long walk: per-tick time (s), torso pitch (rad), pitch rate (rad/s), x, y (m), heading (rad, 0 = +x)."""

    seed: int
    noise: float
    t: np.ndarray
    pitch: np.ndarray
    rate: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    ended: str  # fell, left the lane, timed out


def long_walk(seed: int, noise: float, duration: float, body: Humanoid | None = None) -> Walk:
    """The default gait for ``duration`` s from a start perturbed by ``noise`` rad (seed ``seed``) on the long ground.
    ``body``: a Humanoid with ``LONG_WALK`` parameters and a CPG link to reuse (else one is made and closed)."""
    own = body is None
    if own:
        body = Humanoid(Humanoid.Params(duration=duration, start_noise=noise, **LONG_WALK))
        body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
    rows = []
    original = body.actuate

    def actuate(command):
        original(command)
        turn = body.torso_turn  # the torso frame's axes as columns; row 2 = the world's vertical in the torso frame
        up = turn[2]
        forward = turn[:, 0]
        rows.append(
            (
                body.t,
                math.atan2(-up[0], up[2]),  # as the body's torso_pitch sensor
                float(body.torso_spin[1]),  # gyro, about the torso's own y axis
                body.torso_position[0],
                body.torso_position[1],
                math.atan2(forward[1], forward[0]),
            )
        )

    body.actuate = actuate
    try:
        result = body.handle(TrialRequest(trial_id=seed, seed=seed, body_params={}, controller_params={}, log=False))
    finally:
        body.actuate = original
        if own:
            body.close()
    m = result.metrics
    ended = "fell" if m["fell"] else "left the lane" if m["left_lane"] else "timed out"
    t, pitch, rate, x, y, heading = (np.array(column) for column in zip(*rows, strict=True))
    return Walk(seed, noise, t, pitch, rate, x, y, np.unwrap(heading), ended)


def smooth(values: np.ndarray, dt: float, window: float = SMOOTH) -> np.ndarray:
    """Centred moving average over ``window`` s (an odd number of samples; the ends average what there is)."""
    n = max(1, int(round(window / dt)) // 2 * 2 + 1)
    if n == 1:
        return values.astype(float)
    kernel = np.ones(n)
    total = np.convolve(values, kernel, mode="same")
    count = np.convolve(np.ones(len(values)), kernel, mode="same")
    return total / count


def section_returns(t: np.ndarray, angle: np.ndarray, rate: np.ndarray, sign: int = -1) -> tuple[np.ndarray, ...]:
    """The crossings of the section rate = 0 in one direction (``sign`` -1: rate from + to -, the angle's maxima;
    +1: from - to +, its minima): (times s, angles there), each linearly interpolated between the two samples."""
    before, after = rate[:-1], rate[1:]
    if sign < 0:
        hit = np.flatnonzero((before > 0) & (after <= 0))
    else:
        hit = np.flatnonzero((before < 0) & (after >= 0))
    share = before[hit] / (before[hit] - after[hit])  # where between the samples the rate is 0
    times = t[hit] + share * (t[hit + 1] - t[hit])
    values = angle[hit] + share * (angle[hit + 1] - angle[hit])
    return times, values


@dataclass
class ReturnMap:
    """r_{n+1} = intercept + slope r_n, least squares; the fixed point where it meets the diagonal."""

    intercept: float
    slope: float
    slope_error: float  # standard error of the slope
    fixed_point: float

    @property
    def stable(self) -> bool:
        return abs(self.slope) < 1


def fit_return_map(returns: np.ndarray) -> ReturnMap:
    """Fit the first-return map of the sequence ``returns`` (at least 3 values)."""
    r = np.asarray(returns, dtype=float)
    if len(r) < 3:
        raise ValueError(f"expected at least 3 returns to fit a map; got {len(r)}")
    current, following = r[:-1], r[1:]
    design = np.stack([np.ones_like(current), current], axis=1)
    (intercept, slope), *_ = np.linalg.lstsq(design, following, rcond=None)
    residual = following - design @ np.array([intercept, slope])
    spread = np.sum((current - current.mean()) ** 2)
    dof = max(len(current) - 2, 1)
    slope_error = float(math.sqrt(np.sum(residual**2) / dof / spread)) if spread > 0 else math.inf
    fixed = intercept / (1 - slope) if slope != 1 else math.nan
    return ReturnMap(float(intercept), float(slope), slope_error, float(fixed))


def settled_after(times: np.ndarray, returns: np.ndarray, steady_from: float = SETTLE) -> int:
    """How many returns come before the last one more than 3 s.d. from the steady mean (0: all within)."""
    steady = returns[times >= steady_from]
    if len(steady) < 2:
        return len(returns)  # no steady state to settle on
    away = np.flatnonzero(np.abs(returns - steady.mean()) > 3 * steady.std())
    return int(away[-1]) + 1 if len(away) else 0


def analyse(walk: Walk, window: float = 0.0) -> dict:
    """The walk's section returns and their maps (see the module docstring): the step map (every crossing) and the
    stride maps (every second crossing, the two branches of a left and a right step). ``window``: s of moving average
    on pitch and rate first (0: the signals as measured)."""
    dt = float(np.median(np.diff(walk.t)))
    times, returns = section_returns(walk.t, smooth(walk.pitch, dt, window), smooth(walk.rate, dt, window))
    steady = returns[times >= SETTLE]
    outside = np.flatnonzero(np.abs(walk.y) > DEFAULT_LANE)
    return {
        "times": times,
        "returns": returns,
        "map": fit_return_map(returns),
        "steady_mean": float(steady.mean()) if len(steady) else math.nan,
        "steady_sd": float(steady.std()) if len(steady) else math.nan,
        "steady_map": fit_return_map(steady) if len(steady) >= 3 else None,
        "branches": [fit_return_map(returns[k::2]) for k in (0, 1)],
        "branch_means": [
            float(np.mean(returns[k::2][times[k::2] >= SETTLE])) if len(steady) > 1 else math.nan for k in (0, 1)
        ],
        "settled_after": settled_after(times, returns),
        "left_default_lane": float(walk.t[outside[0]]) if len(outside) else None,
    }


def cobweb(ax, returns: np.ndarray, fit: ReturnMap, color, label: str, first: int = 6) -> None:
    """The map's points (r_n, r_{n+1}), the fitted line and the cobweb of the first ``first`` returns."""
    r = returns
    ax.plot(r[:-1], r[1:], ".", color=color, alpha=0.25, markersize=3)
    low, high = float(r.min()), float(r.max())
    ax.plot(
        [low, high],
        [fit.intercept + fit.slope * low, fit.intercept + fit.slope * high],
        "-",
        color=color,
        lw=1,
        label=f"{label}: r* {fit.fixed_point:.3f}, slope {fit.slope:+.2f}",
    )
    xs, ys = [r[0]], [r[0]]
    for n in range(min(first, len(r) - 1)):
        xs += [r[n], r[n + 1]]
        ys += [r[n + 1], r[n + 1]]
    ax.plot(xs, ys, "-", color=color, lw=1.5)
    for n in range(min(4, len(r))):
        ax.annotate(f"r{n}", (r[n], r[n]), fontsize=7, color=color, xytext=(3, -8), textcoords="offset points")


def figure(walks: list[Walk], results: list[dict], path: Path, window: float = 0.0) -> None:
    """Phase diagram of the first walk; the step map's cobwebs of every walk; every walk's path on the ground."""
    fig, (phase, web, ground) = plt.subplots(1, 3, figsize=(17, 5.5), gridspec_kw={"width_ratios": [1, 1, 0.8]})
    colors = plt.cm.tab10.colors
    walk, result = walks[0], results[0]
    dt = float(np.median(np.diff(walk.t)))
    p, r = smooth(walk.pitch, dt, window), smooth(walk.rate, dt, window)
    edge = int(round(window / dt))
    inside = slice(edge, len(p) - edge)  # not the averages cut by the ends
    phase.plot(p[inside], r[inside], lw=0.3, color="0.6", label="(pitch, pitch rate)")
    early = inside.start + np.flatnonzero(walk.t[inside] < 5.0)
    phase.plot(p[early], r[early], lw=1.0, color=colors[0], label="first 5 s")
    phase.plot(result["returns"], np.zeros_like(result["returns"]), "|", color="k", label="section returns r_n")
    phase.set_xlabel("torso pitch, rad (+ = forward)")
    phase.set_ylabel("torso pitch rate, rad/s")
    phase.set_title(f"phase diagram, seed {walk.seed}, start_noise {walk.noise:g} rad, {walk.t[-1]:.0f} s")
    phase.legend(fontsize=7)
    every = np.concatenate([res["returns"] for res in results])
    low, high = float(every.min()), float(every.max())
    margin = 0.05 * (high - low)
    web.plot([low - margin, high + margin], [low - margin, high + margin], "k--", lw=0.8, label="diagonal")
    for k, (walk, res) in enumerate(zip(walks, results, strict=True)):
        cobweb(web, res["returns"], res["map"], colors[k % 10], f"seed {walk.seed}, noise {walk.noise:g}")
    web.set_xlabel("r_n, rad")
    web.set_ylabel("r_{n+1}, rad")
    web.set_title("step map on pitch rate = 0 (+ to -), cobweb of r_0..r_6")
    web.legend(fontsize=7)
    for k, walk in enumerate(walks):
        ground.plot(walk.x, walk.y, lw=0.8, color=colors[k % 10], label=f"seed {walk.seed}, noise {walk.noise:g}")
    ground.axhspan(-DEFAULT_LANE, DEFAULT_LANE, color="0.9", label="the default lane")
    ground.set_xlabel("x, m")
    ground.set_ylabel("y, m")
    ground.set_title("the torso's path (top view)")
    ground.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=250.0, help="s (L1401: 250)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--noise", type=float, nargs="+", default=[0.02], help="start_noise values, rad")
    parser.add_argument("--figure", type=Path, default=ROOT / "docs/results/chapter4/e4_5_cobweb.png")
    parser.add_argument("--save", type=Path, default=None, help="an .npz of every walk's per-tick traces")
    parser.add_argument("--load", type=Path, default=None, help="analyse the walks of a --save file instead")
    parser.add_argument("--smooth", type=float, default=0.0, help=f"s of moving average first (0: none; {SMOOTH})")
    args = parser.parse_args()
    walks, results, clock = [], [], []
    if args.load:  # walks saved by --save: the same walks (the body and the controller are deterministic)
        saved = np.load(args.load)
        for key in sorted(k for k in saved.files if k.startswith("t_")):
            _, seed, noise = key.split("_")
            columns = {name: saved[f"{name}_{seed}_{noise}"] for name in ("t", "pitch", "rate", "x", "y", "heading")}
            walks.append(Walk(int(seed), float(noise), **columns, ended=str(saved[f"ended_{seed}_{noise}"])))
            clock.append(float(saved[f"wall_{seed}_{noise}"]))
            results.append(analyse(walks[-1], args.smooth))
    for noise in [] if args.load else args.noise:
        body = Humanoid(Humanoid.Params(duration=args.duration, start_noise=noise, **LONG_WALK))
        body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
        for seed in args.seeds:
            start = time.perf_counter()
            walks.append(long_walk(seed, noise, args.duration, body))
            clock.append(time.perf_counter() - start)
            results.append(analyse(walks[-1], args.smooth))
        body.close()
    wall_time = "" if args.load else f" (wall time {sum(clock):.0f} s)"
    print(f"### Walks of {walks[0].t[-1]:.0f} s{wall_time}\n")
    print(
        "| seed | start_noise rad | ended | time s | x m | y m | heading deg | left a +-0.5-m lane at s | returns | "
        "wall s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for walk, res, wall in zip(walks, results, clock, strict=True):
        lane = f"{res['left_default_lane']:.1f}" if res["left_default_lane"] is not None else "never"
        print(
            f"| {walk.seed} | {walk.noise:g} | {walk.ended} | {walk.t[-1]:.1f} | {walk.x[-1]:+.1f} | {walk.y[-1]:+.1f} "
            f"| {math.degrees(walk.heading[-1]):+.0f} | {lane} | {len(res['returns'])} | {wall:.0f} |".replace(
                "| nan |", "| - |"
            )
        )
    signals = f"smoothed over {args.smooth:g} s" if args.smooth > 0 else "as measured"
    print(f"\n### Return map of the torso pitch on Sigma: pitch rate = 0, + to - (rad; pitch and rate {signals})\n")
    print(
        "Step map: r_{n+1} against r_n over every crossing (one per step); stride maps: r_{n+2} against r_n, the "
        "crossings of one branch (A: r_0, r_2, ...; B: r_1, r_3, ...), one per gait cycle. r* and slope b of the "
        f"least-squares line; steady = after {SETTLE:g} s; settled after = returns before the last one more than "
        "3 s.d. from the steady mean.\n"
    )
    print(
        "| seed | noise | r_0 | r_1 | r_2 | r_3 | steady mean +- s.d. | settled after | step map r*, b | "
        "step map (steady) r*, b | stride A r*, b | stride B r*, b |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for walk, res in zip(walks, results, strict=True):
        r, fit, steady = res["returns"], res["map"], res["steady_map"]
        first = " | ".join(f"{v:.4f}" for v in r[:4])
        maps = (fit, steady, *res["branches"])
        cells = [f"{m.fixed_point:.4f}, {m.slope:+.2f} +- {m.slope_error:.2f}" if m else "-" for m in maps]
        settled = min(res["settled_after"], len(res["times"]) - 1)
        print(
            f"| {walk.seed} | {walk.noise:g} | {first} | {res['steady_mean']:.4f} +- {res['steady_sd']:.4f} | "
            f"{res['settled_after']} ({res['times'][settled]:.1f} s) | {' | '.join(cells)} |"
        )
    figure(walks, results, args.figure, args.smooth)
    print(f"\nfigure: {args.figure.relative_to(ROOT) if args.figure.is_relative_to(ROOT) else args.figure}")
    if args.save:
        columns = {
            f"{name}_{w.seed}_{w.noise:g}": getattr(w, name)
            for w in walks
            for name in ("t", "pitch", "rate", "x", "y", "heading", "ended")
        }
        walls = {f"wall_{w.seed}_{w.noise:g}": wall for w, wall in zip(walks, clock, strict=True)}
        np.savez_compressed(args.save, **columns, **walls)


if __name__ == "__main__":
    main()
