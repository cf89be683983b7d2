"""E4.5 (thesis L1401-1413): the stability of a gait by a Poincaré return map of the torso's pitch.

The thesis walks NAO 250 s (400 steps), draws the phase diagram of the torso's inclination to the vertical, takes the
section Sigma "in one direction with null velocity" and shows the first returns r_0..r_3 approaching a fixed point
r* = 0.046 where the cobweb meets the diagonal, "globally stable" (L1408).

Choices not in the thesis (CPG-HUMANOID.md §0.8), kept from the first analysis of our walks: Sigma = the samples where
the pitch rate (the gyro about the torso's own y axis) goes from + to - (the pitch's maxima: the torso's most forward
lean of each step); the return r_n = the pitch there, linearly interpolated between the two samples. The map is
fitted as r_{n+1} = a + b r_n by least squares over all returns of a walk: fixed point r* = a / (1 - b), slope b
(stable if |b| < 1), with the steady state (after ``SETTLE`` s). The orbit crosses Sigma once per step, twice per gait
cycle: the stride maps (every second return, two branches) are the return maps of the cycle.

``sfl report`` runs this on a conditions run whose protocol lists ``analyses: [{kind: poincare}]``, reading each logged
trial's ``body/torso/pitch`` and ``body/torso/pitch_rate`` (and ``body/path/x``, ``y``) from the recording: the body
must be logged on every trial (``record.body_every: 1``) at every control tick (``record.signals_hz: 0``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SETTLE = 10.0  # s: returns after this are the steady state


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


def analyse(t: np.ndarray, pitch: np.ndarray, rate: np.ndarray) -> dict | None:
    """A walk's section returns and maps: the step map (every crossing), its steady part, and the stride maps (every
    second crossing, the two branches of a left and a right step); None with fewer than 3 returns. ``t`` in s from
    the walk's start, ``pitch`` in rad, ``rate`` in rad/s."""
    times, returns = section_returns(t, pitch, rate)
    if len(returns) < 3:
        return None
    steady = returns[times >= SETTLE]
    return {
        "times": times,
        "returns": returns,
        "map": fit_return_map(returns),
        "steady_mean": float(steady.mean()) if len(steady) else math.nan,
        "steady_sd": float(steady.std()) if len(steady) else math.nan,
        "steady_map": fit_return_map(steady) if len(steady) >= 3 else None,
        "branches": [fit_return_map(returns[k::2]) if len(returns[k::2]) >= 3 else None for k in (0, 1)],
        "settled_after": settled_after(times, returns),
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
