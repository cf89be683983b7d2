"""The network's RK4 (network.py ``CPGNetwork._integrate``) compiled with numba: ``kernel="numba"`` (issue 31).

The same equations, written per cell as the thesis writes them, for every batch copy:

    tau_m dV/dt = -(fast(V, sigma_f) + q - i_syn - i_ext)          (4.1) L1065, fast (4.4) L1073
    tau_s dq/dt = -q + sigma (V - E_s)                             (4.2) L1067, (4.6) L1081 / (4.8) L1089
    i_syn = sum_k w_k tanh(V_k / A_f)                              (§7.3: bounded presynaptic output)

with classic RK4 (§7.2), y(t + h) = y + h/6 (k1 + 2 (k2 + k3) + k4). The per-tick constants (i_ext / tau_m and
-sigma_s E_s / tau_s, ``CPGNetwork._per_tick_constant``) are added as the numpy step adds them, so the sums are the same
up to their order: commands within 1e-9 of the numpy step's over a walk (tests/test_cpg_kernel.py).

numpy pays about a microsecond per call on arrays of 24 cells, and its step needs 21 calls per RK4 step: 210 per
10-ms tick. Compiled, the whole tick is one call. numba is optional (``pip install -e '.[fast]'``): without it the
network integrates with numpy. The first call compiles (about a second; then cached on disk, ``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


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
    for c in range(b):
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
                    out[i] = math.tanh(Y[0, i] / A_f)  # the presynaptic output (§7.3)
                for i in range(n):
                    V, q = Y[0, i], Y[1, i]
                    i_syn = 0.0
                    for p in range(rows[i], rows[i + 1]):
                        i_syn += weights[p] * out[sources[p]]
                    fast = V - A_f * math.tanh((sigma_f[c, i] / A_f) * V)  # (4.4)
                    k[s, 0, i] = -(fast + q - i_syn) / tau_m + constant[c, i]  # (4.1)
                    dq = (sigma_s[c, i] * V - q) / tau_s + constant[c, n + i]  # (4.2), (4.6)
                    if split:  # (4.8): sigma_in below E_s, sigma_out above, instead of sigma_s
                        sigma = sigma_in[c, i] if V < E_s else sigma_out[c, i]
                        dq += (sigma - sigma_s[c, i]) * (V - E_s) / tau_s
                    k[s, 1, i] = dq
            for i in range(n):
                for side in range(2):
                    y[c, side, i] += h / 6.0 * ((k[0, side, i] + 2.0 * (k[1, side, i] + k[2, side, i])) + k[3, side, i])
