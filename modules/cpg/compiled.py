"""The network's RK4 (network.py ``CPGNetwork._integrate``) compiled with numba: ``kernel="numba"`` (issue 31).

The same equations, written per cell as the thesis writes them, for every batch copy:

    tau_m dV/dt = -(fast(V, sigma_f) + q - i_syn - i_ext)          (4.1) L1065, fast (4.4) L1073
    tau_s dq/dt = -q + sigma (V - E_s)                             (4.2) L1067, (4.6) L1081 / (4.8) L1089
    i_syn = sum_k w_k tanh(V_k / A_f)                              (§7.3: bounded presynaptic output)

with classic RK4 (§7.2), y(t + h) = y + h/6 (k1 + 2 (k2 + k3) + k4). The per-tick constants (i_ext / tau_m and
-sigma_s E_s / tau_s, ``CPGNetwork._per_tick_constant``) are added as the numpy step adds them, so the sums are the same
up to their order: commands within 1e-9 of the numpy step's over a walk (tests/modules/test_cpg_kernel.py).

numpy pays about a microsecond per call on arrays of 24 cells, and its step needs 21 calls per RK4 step: 210 per
10-ms tick. Compiled, the whole tick is one call, whose cost is then its 1,920 hyperbolic tangents (two per cell per
RK4 stage): :func:`tanh` takes them from one ``exp`` each, cheaper than the C library's ``tanh`` and within 2.3e-16 of
it (absolute, over [-25, 25]); ``benchmarks/cpg.py`` times the tick. numba is optional (``pip install -e '.[fast]'``):
without it the network integrates with numpy. The first call compiles (about a second; then cached on disk,
``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def tanh(x):
    """tanh x = sign(x) (1 - e) / (1 + e) with e = exp(-2 |x|): one ``exp``, no cancellation for large |x|; within
    2.3e-16 of ``math.tanh`` (absolute; the relative error grows below |x| ~ 1e-8, where both are about x); NaN
    passes, +-inf gives +-1."""
    e = math.exp(-2.0 * abs(x))
    t = (1.0 - e) / (1.0 + e)
    return t if x >= 0.0 else -t


@njit(cache=True)
def rk4_steps(
    y,
    h,
    substeps,
    tau_m,
    tau_s,
    A_f,
    E_s,
    sigma_s,
    sigma_f,
    sigma_in,
    sigma_out,
    split,
    rows,
    sources,
    weights,
    constant,
):
    """``substeps`` RK4 steps of length h (s), in place on ``y`` (batch, 2, n) = [V, q] per copy.

    ``sigma_*`` (batch, n); ``split``: (4.8)'s sigma_in / sigma_out instead of sigma_s; the couplings W[target, source]
    (the intra-joint RG-E <-> RG-F synapse included) as rows: cell i's synapses are ``sources[rows[i]:rows[i + 1]]``
    with ``weights`` alike; ``constant`` (batch, 2 n): [i_ext / tau_m, -sigma_s E_s / tau_s] of this tick."""
    b, _, n = y.shape
    k = np.empty((4, 2, n))
    Y = np.empty((2, n))
    out = np.empty(n)
    slope = np.empty(n)
    over_tau_m, over_tau_s, over_A_f = 1.0 / tau_m, 1.0 / tau_s, 1.0 / A_f  # multiplications in the loop, not divisions
    for c in range(b):
        for i in range(n):
            slope[i] = sigma_f[c, i] / A_f  # tanh((sigma_f / A_f) V) of (4.4)
        for _ in range(substeps):
            for s in range(4):
                step = 0.0 if s == 0 else (0.5 * h if s < 3 else h)  # Y_s = y + c_s k_{s-1}
                for i in range(n):
                    if s == 0:
                        Y[0, i] = y[c, 0, i]
                        Y[1, i] = y[c, 1, i]
                    else:
                        Y[0, i] = y[c, 0, i] + step * k[s - 1, 0, i]
                        Y[1, i] = y[c, 1, i] + step * k[s - 1, 1, i]
                    out[i] = tanh(Y[0, i] * over_A_f)  # the presynaptic output (§7.3)
                for i in range(n):
                    V, q = Y[0, i], Y[1, i]
                    i_syn = 0.0
                    for p in range(rows[i], rows[i + 1]):
                        i_syn += weights[p] * out[sources[p]]
                    fast = V - A_f * tanh(slope[i] * V)  # (4.4)
                    k[s, 0, i] = -(fast + q - i_syn) * over_tau_m + constant[c, i]  # (4.1)
                    dq = (sigma_s[c, i] * V - q) * over_tau_s + constant[c, n + i]  # (4.2), (4.6)
                    if split:  # (4.8): sigma_in below E_s, sigma_out above, instead of sigma_s
                        sigma = sigma_in[c, i] if V < E_s else sigma_out[c, i]
                        dq += (sigma - sigma_s[c, i]) * (V - E_s) * over_tau_s
                    k[s, 1, i] = dq
            for i in range(n):
                for side in range(2):
                    y[c, side, i] += h / 6.0 * ((k[0, side, i] + 2.0 * (k[1, side, i] + k[2, side, i])) + k[3, side, i])


@njit(cache=True)
def layers(
    rho,
    V,
    w_sensory,
    w_rg2pf,
    bounded,
    A_f,
    pf_divisor,
    pf_half_slope,
    pf_centre,
    w_pf2mn,
    mn_divisor,
    mn_half_slope,
    mn_theta,
):
    """PF (4.9)-(4.10) and MN (4.11)-(4.12) of every cell from V at the end of the tick and the sensory neurons ``rho``
    (batch, sensory), as ``CPGNetwork._outputs`` computes them; returns (PF, MN), each (batch, n).

    I_PF = (w_rg2pf RG + sum_j w_j S_j) / (n_PF + 1), PF = sigmoid(alpha alpha_MLR (I_PF - (theta + theta_MLR)))
    I_MN = (w_pf2mn PF + sum_j w_j S_j) / (n_MN + 1), MN = sigmoid(alpha (I_MN - theta))
    with sigmoid(2 a x) = (1 + tanh(a x)) / 2 (``_logistic``); RG = V, or tanh(V / A_f) when ``bounded``."""
    b, n = V.shape
    pf, mn = np.empty((b, n)), np.empty((b, n))
    for c in range(b):
        for i in range(n):
            drive_pf, drive_mn = 0.0, 0.0
            for j in range(rho.shape[1]):
                drive_pf += rho[c, j] * w_sensory[j, i]
                drive_mn += rho[c, j] * w_sensory[j, n + i]
            rg = math.tanh(V[c, i] / A_f) if bounded else V[c, i]
            I_pf = (w_rg2pf[i] * rg + drive_pf) / pf_divisor[i]  # (4.10) L1110
            pf[c, i] = 0.5 * (1.0 + math.tanh(pf_half_slope[c, i] * (I_pf - pf_centre[c, i])))  # (4.9) L1108
            I_mn = (w_pf2mn[i] * pf[c, i] + drive_mn) / mn_divisor[i]  # (4.12) L1125
            mn[c, i] = 0.5 * (1.0 + math.tanh(mn_half_slope * (I_mn - mn_theta)))  # (4.11) L1123
    return pf, mn
