"""The cells of the MLMP-CPG (thesis ch. 4), one function per equation, readable: (4.1)-(4.13).

``CPGNetwork`` (network.py) computes exactly these, vectorised over every cell of every joint (and, with
``kernel: numba``, compiled.py per cell); the tests check the network against them (tests/modules/test_cpg.py).
"""

from __future__ import annotations

import numpy as np

E, F = 0, 1  # side index: neuron 2 j + E is joint j's extensor chain, 2 j + F its flexor chain


def fast_current(V, sigma_f, A_f):
    """(4.4) L1073: fast(V, sigma_f) = V - A_f tanh((sigma_f / A_f) V)."""
    return V - A_f * np.tanh((sigma_f / A_f) * V)


def slow_steady_state(V, sigma_in, sigma_out, E_s):
    """(4.6) L1081 / (4.8) L1089: q_inf = sigma (V - E_s), sigma = sigma_in below E_s, sigma_out above
    (both = sigma_s for (4.6))."""
    return np.where(V < E_s, sigma_in, sigma_out) * (V - E_s)


def rhythm_generator(V, q, i_inj, sigma_s, sigma_f, tau_m, tau_s, A_f, E_s):
    """Time derivatives (dV/dt, dq/dt) of the Rowat-Selverston cell, 1/s.

    (4.1) L1065: tau_m dV/dt = -(fast(V, sigma_f) + q - i_inj)
    (4.2) L1067: tau_s dq/dt = -q + q_inf(V)"""
    dV = -(fast_current(V, sigma_f, A_f) + q - i_inj) / tau_m
    dq = (-q + slow_steady_state(V, sigma_s, sigma_s, E_s)) / tau_s
    return dV, dq


def sigmoid(x):
    """1 / (1 + exp(-x)), written as (1 + tanh(x / 2)) / 2 so that it cannot overflow."""
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _logistic(half_slope, x):
    """sigmoid(2 half_slope x), in place on ``x`` (a fresh array): the hot path's form of (4.9), (4.11), (4.13). The
    same numbers as ``sigmoid``: halving is exact in floating point, so 0.5 (a x) = (0.5 a) x."""
    np.multiply(x, half_slope, out=x)
    np.tanh(x, out=x)
    x += 1.0
    x *= 0.5
    return x


def pattern_formation(I, alpha, alpha_mlr, theta, theta_mlr):
    """(4.9) L1108: PF = 1 / (1 + exp(alpha alpha_MLR ((theta + theta_MLR) - I)))."""
    return sigmoid(alpha * alpha_mlr * (I - (theta + theta_mlr)))


def motor_neuron(I, alpha, theta):
    """(4.11) L1123: MN = 1 / (1 + exp(alpha (theta - I)))."""
    return sigmoid(alpha * (I - theta))


def sensory_neuron(phi, alpha, theta):
    """(4.13) L1133: rho = 1 / (1 + exp(alpha (theta - phi))); phi an angle (rad) or a force (N)."""
    return sigmoid(alpha * (phi - theta))


def averaged_input(main_weight, main, sensory_weights, sensory, n):
    """(4.10) L1110 / (4.12) L1125: I = (w main + sum_j w_j S_j) / (n + 1); ``sensory_weights`` is
    (sensory neurons, neurons), ``n`` the number of sensory synapses of each neuron."""
    drive = main_weight * main
    if sensory_weights.size:
        drive = drive + sensory @ sensory_weights
    return drive / (n + 1)
