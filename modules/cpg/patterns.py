"""Motion patterns of a CPG joint: the energy metric (4.15), a pattern classifier, and the pattern space.

The thesis names four patterns of a joint over (sigma_s, sigma_f) (Fig. 4.5, L1143-1154): plateau (x),
quiescence (*), almost an oscillator (+) and oscillation (o), and orders them by the energy of the joint's
motion (4.15) L1296, one log-energy axis per joint (L1294, Fig. 4.16). It gives no numerical criteria for the
classes nor the energy's time window; the ones below are chosen here and said where they are defined.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .circuit import Circuit, validate_circuit
from .network import CPGNetwork

PLATEAU, QUIESCENT, ALMOST_OSCILLATOR, OSCILLATOR = "plateau", "quiescent", "almost_oscillator", "oscillator"
KINDS = (PLATEAU, QUIESCENT, ALMOST_OSCILLATOR, OSCILLATOR)

#: one (sigma_s, sigma_f) of each class, to switch a joint to a pattern by name (digest §7.11): points of the digest's
#: single-cell reference map (CPG-HUMANOID.md §1.7), the same points tests/modules/test_cpg.py classifies: plateau below
#: the line sigma_s = (sigma_f - 1) / 2 (sigma_s = 0), quiescent at sigma_f <= 0.25, almost-oscillator at sigma_f in
#: [0.5, 1], oscillator at (2, 2) (period 1.25 s).
PATTERN_POINTS = {
    PLATEAU: (0.0, 2.0),
    QUIESCENT: (1.0, 0.25),
    ALMOST_OSCILLATOR: (4.0, 0.75),
    OSCILLATOR: (2.0, 2.0),
}

# The single-cell kick of the digest's reference map (CPG-HUMANOID.md §1.7): +1 into the cell for 80 ms.
KICK_AMPLITUDE = 1.0
KICK_DURATION = 0.08  # s
# Energy window (digest §7.13): from the end of the kick, 10 s.
ENERGY_WINDOW = 10.0  # s


def energy(angle: np.ndarray, dt: float, axis: int = 0) -> np.ndarray:
    """(4.15) L1296: E = integral (d theta / dt)^2 dt over the given samples of the joint angle (rad, every dt s);
    the derivative as finite differences, so E = sum (delta theta)^2 / dt, in rad^2 / s."""
    return np.sum(np.diff(angle, axis=axis) ** 2, axis=axis) / dt


def log_energy(angle: np.ndarray, dt: float, axis: int = 0, floor: float = 1e-12) -> np.ndarray:
    """log10 of (4.15) (the thesis plots log E, Fig. 4.16; base 10 for plots, digest §7.13), floored so that a
    still joint is finite."""
    return np.log10(np.maximum(energy(angle, dt, axis), floor))


def windowed_energy(trace: np.ndarray, dt: float, window: float) -> np.ndarray:
    """(4.15) L1296 over a sliding window: at sample i, E over the last ``window`` s (samples i - n .. i, n =
    window / dt rounded, at least 1), as :func:`energy` computes it; NaN for the first n samples. A trajectory in
    the pattern space of L1430-1435 (Fig. 4.23): one value per joint and time, high while the joint oscillates,
    falling toward 0 once it holds still (plateau, quiescence). Units: those of the trace squared per s."""
    x = np.asarray(trace, dtype=float)
    steps = max(1, int(round(window / dt)))
    total = np.concatenate([[0.0], np.cumsum(np.diff(x) ** 2 / dt)])  # E from the first sample to sample i
    out = np.full(len(x), np.nan)
    out[steps:] = np.maximum(total[steps:] - total[:-steps], 0.0)  # a cumulative sum's rounding: never below 0
    return out


def pattern_space_point(angles: dict[str, np.ndarray], dt: float) -> dict[str, float]:
    """The point of a run in the pattern space: one log-energy axis per joint (L1294), from each joint's angle
    trace over the same window."""
    return {joint: float(log_energy(np.asarray(trace), dt)) for joint, trace in angles.items()}


@dataclass(frozen=True)
class Pattern:
    """A classified trace: ``kind`` one of KINDS; ``frequency`` in Hz for an oscillator (else NaN)."""

    kind: str
    frequency: float = float("nan")


def classify(
    trace: np.ndarray,
    dt: float,
    kick_end: float,
    rest: float = 0.0,
    oscillation_amplitude: float = 1.0,
    band: float = 0.02,
) -> Pattern:
    """Classify the response of a cell (or joint) to a kick that ended at ``kick_end`` s. ``trace`` sampled every
    ``dt`` s from t = 0, ``rest`` its resting value. Criteria, chosen here (the thesis gives none):

    - oscillator: over the last half of the post-kick trace, the peak-to-peak is above ``oscillation_amplitude``
      (1 model mV = A_f / 5) in both quarters (sustained, not a decaying ring), with at least two upward crossings
      of its mid-level; frequency = 1 / the mean interval between those crossings;
    - plateau: not oscillating, and the last half stays away from rest: outside the settling band, ``band`` (2 %,
      the usual settling band) of the trace's largest excursion after the kick;
    - almost oscillator: back at rest (inside the band) through a damped oscillation: outside the band, it crosses
      rest at least twice (through rest and back);
    - quiescent: back at rest without swinging back (one undershoot, the slow current's after-hyperpolarisation,
      is not an oscillation; a first version that called any 5 % undershoot "almost an oscillator" labelled
      most of the sigma_f <= 0.25 column so, and a first plateau level of 1 mV missed the plateau at V = 0.83 of
      sigma_f = 17.5; see docs/results/chapter4.md).
    """
    x = np.asarray(trace, dtype=float) - rest
    post = x[int(round(kick_end / dt)) :]
    tail = post[len(post) // 2 :]
    quarter = len(tail) // 2
    spans = np.ptp(tail[:quarter]), np.ptp(tail[quarter:])
    if min(spans) > oscillation_amplitude:
        mid = 0.5 * (tail.max() + tail.min())
        above = tail > mid
        upward = np.flatnonzero(~above[:-1] & above[1:])
        if len(upward) >= 2:
            return Pattern(OSCILLATOR, float(1.0 / (np.mean(np.diff(upward)) * dt)))
    excursion = np.max(np.abs(post))
    if abs(np.mean(tail)) > band * excursion:
        return Pattern(PLATEAU)
    outside = post[np.abs(post) > band * excursion]  # the samples outside the settling band around rest
    crossings = np.count_nonzero(np.diff(np.sign(outside)))
    return Pattern(ALMOST_OSCILLATOR if crossings >= 2 else QUIESCENT)


def one_joint_circuit(
    rg_mutual: float = 0.0, pf_alpha: float = 1.0, gain: float = 1.0, w_rg2pf: float = 1.0, pf_input: str = "potential"
) -> Circuit:
    """A single joint, no sensors, position command theta = gain (MN_E - MN_F), kicked at t = 0 with +1 into RG-F
    (-1 into RG-E) for 80 ms (digest §1.7). ``rg_mutual`` = 0 makes E and F two independent mirror cells (the
    digest's single-cell reference); Table 4.1's -1 couples them. ``w_rg2pf`` = 0.2 gives the PF input of an ankle
    pitch PF (RG / (n + 1) with n = 4 silent sensors, (4.10)). ``pf_input``: what the PF reads of the RG
    (circuit.py)."""
    return validate_circuit(
        {
            "name": "one_joint",
            "command": "position",
            "pf_input": pf_input,
            "joints": [
                {
                    "name": "joint",
                    "rg": {"sigma_s": 1.0, "sigma_f": 1.0},
                    "pf": {"alpha": pf_alpha},
                    "rg_mutual": rg_mutual,
                    "w_rg2pf": w_rg2pf,
                    "gain": gain,
                }
            ],
            "kicks": [{"joints": ["joint"], "start": 0.0, "duration": KICK_DURATION, "amplitude": KICK_AMPLITUDE}],
        }
    )


def simulate_one_joint(
    sigma_s,
    sigma_f,
    duration: float = 20.0,
    rg_mutual: float = 0.0,
    pf_alpha: float = 1.0,
    theta_mlr=0.0,
    w_rg2pf: float = 1.0,
    pf_input: str = "potential",
    control_dt: float = 0.01,
    substeps: int = 10,
) -> dict[str, np.ndarray]:
    """Run one joint for every (sigma_s, sigma_f) pair at once (a batch of networks, one array update per RK4
    stage). Returns traces sampled every control tick, each (ticks + 1, pairs): ``time`` (s), ``V_E``, ``V_F``
    (RG membrane potentials), ``MN_E``, ``MN_F`` and ``angle`` (the position command, rad)."""
    sigma_s, sigma_f = (np.atleast_1d(np.asarray(x, dtype=float)) for x in (sigma_s, sigma_f))
    sigma_s, sigma_f = np.broadcast_arrays(sigma_s, sigma_f)
    network = CPGNetwork(one_joint_circuit(rg_mutual, pf_alpha, w_rg2pf=w_rg2pf, pf_input=pf_input), batch=sigma_s.size)
    network.set_pattern(sigma_s.reshape(-1, 1), sigma_f.reshape(-1, 1))
    network.set_descending(theta_mlr=np.reshape(theta_mlr, (-1, 1)) if np.ndim(theta_mlr) else theta_mlr)
    ticks = int(round(duration / control_dt))
    out = {name: np.empty((ticks + 1, sigma_s.size)) for name in ("V_E", "V_F", "MN_E", "MN_F", "angle")}

    def record(i: int) -> None:
        V, mn = network.membrane_potential[:, 0], network.motor_neuron[:, 0]
        out["V_E"][i], out["V_F"][i] = V[:, 0], V[:, 1]
        out["MN_E"][i], out["MN_F"][i] = mn[:, 0], mn[:, 1]
        out["angle"][i] = network.command()[:, 0]

    record(0)
    for i in range(1, ticks + 1):
        network.advance(None, control_dt, substeps)
        record(i)
    out["time"] = np.arange(ticks + 1) * control_dt
    return out
