"""The multi-layered multi-pattern CPG (MLMP-CPG) of thesis chapter 4, as a pure numpy network.

Per joint j there are two chains, extensor (E) and flexor (F), each of

- a rhythm generator (RG): the Rowat-Selverston cell (4.1)-(4.8), state (V, q);
- a pattern formation neuron (PF) (4.9)-(4.10), with the descending modulation alpha_MLR, theta_MLR;
- a motor neuron (MN) (4.11)-(4.12);

fed by sensory neurons (4.13) through the joint's synaptic table (articular reflex ES/FS -> MN, stretch
reflex AS -> knee MN, contact/falling sensors -> ankle PF, ...) and coupled RG -> RG between joints.
Everything is vectorised over all neurons of all joints, and over a batch of independent copies of the
network (a parameter grid is one batch): neuron 2 j is joint j's E, 2 j + 1 its F; the state is one
array ``y`` of shape (batch, 2, 2 n_joints) holding V (``y[:, 0]``) and q (``y[:, 1]``).

Time is in seconds, V and q in the model's millivolts (L1091; tau_m = 0.05 s, tau_s = 1 s, L1617).

Choices where the thesis is silent (CPG-HUMANOID.md, "the digest", §7), followed here:

- §7.1: A_f = 5, E_s = 0 (author's code); current kicks of +I into RG-F and -I into RG-E.
- §7.2: classic RK4 (the author's code has two defects in its q stages; not reproduced), h = 1 ms,
  10 sub-steps per 10-ms control tick, CPG time = simulated time (the code runs CPG time at 1/4 of wall
  time on the robot; not reproduced).
- §7.3: synaptic input to a cell is added to its injected current, i = i_ext + sum_k w_k tanh(V_k / A_f)
  (bounded presynaptic output; raw V at |w| = 1 cancels the leak of (4.4) and diverges). The same
  tanh output carries the intra-joint RG-E <-> RG-F synapse of Table 4.1 (-1). The PF reads V itself.
- §7.5: n in (4.10)/(4.12) = the number of sensory synapses declared on that neuron, zero weights
  included.
- §7.6: theta_MLR enters with opposite signs: theta_eff = theta - theta_MLR on PF-E and theta + theta_MLR
  on PF-F, so +0.5 is extensor domination (L1160).
- §7.7: alpha_MLR literally as in (4.9): the PF slope is alpha * alpha_MLR.
- §7.10: phase resetting = a pulse (default -1 into RG-F, +1 into RG-E, 40 ms) into a joint's RG when a
  sensory neuron (heel contact GB) rises through 0.5; switchable.
- §7.11: pattern switching = new (sigma_s, sigma_f), V = q = 0, theta_0 := the measured angle, then a
  kick of +I (F) / -I (E) for 0.2 s.

What is continuous and what is sampled: the RG states (V, q) and the RG-RG synapses (a function of V)
are integrated with RK4. The injected currents (kicks, phase-reset and switching pulses) and the sensory
neurons are sampled once per control tick and held over its sub-steps (the body's sensors only change
per tick). PF and MN are static functions of V and the sensory neurons, evaluated at the end of the tick.
Resets (switching) happen between ticks.

The network holds no random state: ``reset(seed)`` takes the seed for the module contract only; the
initial state is V = q = 0, as in the author's code (digest §5).
"""

from __future__ import annotations

import numpy as np

from .circuit import Circuit

E, F = 0, 1  # side index: neuron 2 j + E is joint j's extensor chain, 2 j + F its flexor chain
TARGETS = ("PF_E", "PF_F", "MN_E", "MN_F")


# --------------------------------------------------------------------------------------------
# The cell equations, readable (the vectorised step below computes exactly these)
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# The network
# --------------------------------------------------------------------------------------------


class CPGNetwork:
    """A circuit's MLMP-CPG, ``batch`` independent copies of it integrated together.

    ``batch=None`` (the default) is one network whose accessors return arrays without the batch axis.
    Per-copy parameters (``set_pattern``, ``set_descending``) may differ between copies."""

    def __init__(self, circuit: Circuit, batch: int | None = None) -> None:
        self.circuit = circuit
        self.batched = batch is not None
        self.batch = batch or 1
        self.joint_names = [j.name for j in circuit.joints]
        nj = len(circuit.joints)
        self.n_joints, self.n_neurons = nj, 2 * nj
        b, n = self.batch, self.n_neurons
        cell = circuit.cell
        self.tau_m, self.tau_s, self.A_f, self.E_s = cell.tau_m, cell.tau_s, cell.A_f, cell.E_s

        # RG -> RG synapses through tanh(V / A_f) (§7.3): W[target, source]
        W = np.zeros((n, n))
        for j, joint in enumerate(circuit.joints):
            W[2 * j + F, 2 * j + E] += joint.rg_mutual  # Table 4.1: RG-E -> RG-F
            W[2 * j + E, 2 * j + F] += joint.rg_mutual  # Table 4.1: RG-F -> RG-E
        for c in circuit.couplings:
            W[circuit.neuron_index(c.target), circuit.neuron_index(c.source)] += c.weight
        self.coupling = W
        self._coupled = bool(np.any(W))
        self._WT_over_tau_m = W.T / self.tau_m

        # sensory neurons (4.13) and the synaptic tables: PF and MN input weights per neuron
        self.sensor_names = [s.name for s in circuit.sensory_neurons]
        self._sensor_input = np.array([circuit.inputs.index(s.input) for s in circuit.sensory_neurons], dtype=int)
        self._sensor_alpha = np.array([s.alpha for s in circuit.sensory_neurons])
        self._sensor_theta = np.array([s.theta for s in circuit.sensory_neurons])
        ns = len(self.sensor_names)
        weights = {t: np.zeros((n, ns)) for t in TARGETS}  # [neuron, sensory neuron]
        count = {t: np.zeros(n) for t in TARGETS}  # n of (4.10)/(4.12): declared synapses (§7.5)
        for j, joint in enumerate(circuit.joints):
            for source, targets in joint.synapses.items():
                s = self.sensor_names.index(source)
                for target, w in targets.items():
                    neuron = 2 * j + (E if target.endswith("_E") else F)
                    weights[target][neuron, s] += w
                    count[target][neuron] += 1
        self._w_pf = (weights["PF_E"] + weights["PF_F"]).T  # (sensory, neurons); a row has one side's weights only
        self._w_mn = (weights["MN_E"] + weights["MN_F"]).T
        self._n_pf = count["PF_E"] + count["PF_F"]
        self._n_mn = count["MN_E"] + count["MN_F"]
        self._w_rg2pf = np.repeat([j.w_rg2pf for j in circuit.joints], 2)
        self._w_pf2mn = np.repeat([j.w_pf2mn for j in circuit.joints], 2)

        self._load_parameters()
        self.mn_alpha, self.mn_theta = circuit.motor_neuron.alpha, circuit.motor_neuron.theta
        self.gain = np.array([j.gain for j in circuit.joints])
        self._angle_input = [
            None if j.angle_input is None else circuit.inputs.index(j.angle_input) for j in circuit.joints
        ]

        # pulses, triggers
        self._kicks = [
            (np.array([circuit.joint_index(name) for name in k.joints]), k.start, k.duration, k.amplitude)
            for k in circuit.kicks
        ]
        self._resets = [
            (self.sensor_names.index(r.sensor), circuit.joint_index(r.joint), r.amplitude, r.duration, r.threshold)
            for r in circuit.phase_resets
        ]
        self._reset_arrays = tuple(np.array(column) for column in zip(*self._resets, strict=True))

        # buffers of the RK4 hot path
        # the state y (batch, 2, n): V = y[:, 0], q = y[:, 1], inside a buffer [V, q, tanh part] (_update_coefficients)
        self._z0, self._zs = np.zeros((b, 4 * n)), np.zeros((b, 4 * n))
        self.y = self._z0[:, : 2 * n].reshape(b, 2, n)
        self._ys = self._zs[:, : 2 * n].reshape(b, 2, n)
        assert np.shares_memory(self.y, self._z0) and np.shares_memory(self._ys, self._zs)

        def stage(z: np.ndarray, y: np.ndarray) -> tuple:
            return z, y[:, 0:1], z[:, 2 * n :].reshape(b, 2, n), y[:, 0]

        self._stage0, self._stage = stage(self._z0, self.y), stage(self._zs, self._ys)
        assert np.shares_memory(self._stage0[2], self._z0)
        k_flat = [np.zeros((b, 2 * n)) for _ in range(4)]
        self._k = [(k.reshape(b, 2, n), k) for k in k_flat]
        self._constant = np.zeros((b, 2, n))  # (i_ext / tau_m, -sigma_s E_s / tau_s), per tick
        self._has_constant = False
        self.reset(0)

    # ---------------------------------------------------------------- parameters

    def _update_coefficients(self) -> None:
        """The right-hand side of (4.1)-(4.2) for every cell, arranged for the hot path:

        dV/dt = (-V - q + A_f tanh(sigma_f V / A_f) + sum_k w_k tanh(V_k / A_f) + i_ext) / tau_m   (4.1), (4.4), §7.3
        dq/dt = (sigma_s V - q - sigma_s E_s) / tau_s                                               (4.2), (4.6)

        A stage's buffer holds z = [V, q, tanh(sigma_f V / A_f), tanh(V / A_f)] per copy; dy/dt = z @ ``_rhs``
        (+ the per-tick constants), so one derivative is three numpy calls (scale, tanh, dot) whatever the number
        of joints. ``_rhs`` rows: V, q, the fast tanh, the synaptic tanh; columns: dV/dt, dq/dt. When sigma_s
        differs between batch copies (a parameter grid), its term sigma_s V / tau_s is added elementwise instead."""
        n = self.n_neurons
        eye = np.eye(n)
        self._tanh_slope = np.empty((self.batch, 2, n))
        self._tanh_slope[:, 0] = self.sigma_f / self.A_f  # tanh((sigma_f / A_f) V) (4.4)
        self._tanh_slope[:, 1] = 1.0 / self.A_f  # tanh(V / A_f): the presynaptic output (§7.3)
        self._sigma_s_shared = bool(np.all(self.sigma_s == self.sigma_s[0]))
        rhs = np.zeros((4 * n, 2 * n))
        rhs[:n, :n] = -eye / self.tau_m  # -V / tau_m: the leak part of fast() (4.4) in (4.1)
        rhs[n : 2 * n, :n] = -eye / self.tau_m  # -q / tau_m (4.1)
        rhs[2 * n : 3 * n, :n] = eye * (self.A_f / self.tau_m)  # +A_f tanh(sigma_f V / A_f) / tau_m (4.4) in (4.1)
        rhs[3 * n :, :n] = self._WT_over_tau_m  # sum_k w_k tanh(V_k / A_f) / tau_m (§7.3)
        rhs[n : 2 * n, n:] = -eye / self.tau_s  # -q / tau_s (4.2)
        if self._sigma_s_shared:
            rhs[:n, n:] = np.diag(self.sigma_s[0]) / self.tau_s  # sigma_s V / tau_s: q_inf (4.6) in (4.2)
        self._rhs = rhs
        self._sigma_s_over_tau_s = self.sigma_s / self.tau_s
        self._slow_constant = -self.sigma_s * self.E_s / self.tau_s  # -sigma_s E_s / tau_s (4.6)

    def _load_parameters(self) -> None:
        """The circuit's per-copy parameters, (batch, neurons): RG patterns and PF constants."""
        joints, b = self.circuit.joints, self.batch

        def per_neuron(value) -> np.ndarray:
            return np.tile(np.repeat([value(j) for j in joints], 2), (b, 1))

        self.sigma_s = per_neuron(lambda j: j.rg.sigma_s)
        self.sigma_f = per_neuron(lambda j: j.rg.sigma_f)
        self.sigma_in = per_neuron(lambda j: j.rg.sigma_s if j.rg.sigma_in is None else j.rg.sigma_in)
        self.sigma_out = per_neuron(lambda j: j.rg.sigma_s if j.rg.sigma_out is None else j.rg.sigma_out)
        self._split = bool(np.any(self.sigma_in != self.sigma_s) or np.any(self.sigma_out != self.sigma_s))
        self.pf_alpha = per_neuron(lambda j: j.pf.alpha)
        self.pf_theta = per_neuron(lambda j: j.pf.theta)
        self.alpha_mlr = per_neuron(lambda j: j.pf.alpha_mlr)
        theta_mlr = per_neuron(lambda j: j.pf.theta_mlr)
        self.theta_mlr_signed = theta_mlr * np.tile([-1.0, 1.0], self.n_joints)  # §7.6: -theta_MLR on E, + on F
        self.phase_reset_enabled = np.array([r.enabled for r in self.circuit.phase_resets], dtype=bool)
        self.theta0 = np.tile([j.theta0 for j in joints], (b, 1))
        self._update_coefficients()

    def set_pattern(self, sigma_s, sigma_f, joints: list[str] | None = None) -> None:
        """Set (sigma_s, sigma_f) of the named joints (all by default); each broadcast to (batch, joints)."""
        idx = self._joint_indices(joints)
        cols = np.concatenate([2 * idx + E, 2 * idx + F])
        for array, value in ((self.sigma_s, sigma_s), (self.sigma_f, sigma_f)):
            v = np.broadcast_to(np.asarray(value, dtype=float), (self.batch, len(idx)))
            array[:, cols] = np.concatenate([v, v], axis=1)
        self.sigma_in[:, cols] = self.sigma_s[:, cols]
        self.sigma_out[:, cols] = self.sigma_s[:, cols]
        self._split = bool(np.any(self.sigma_in != self.sigma_s) or np.any(self.sigma_out != self.sigma_s))
        self._update_coefficients()

    def set_descending(self, alpha_mlr=None, theta_mlr=None, joints: list[str] | None = None) -> None:
        """Descending (MLR) control of the named joints' PF neurons (4.9); theta_MLR with the signs of §7.6."""
        idx = self._joint_indices(joints)
        cols = np.concatenate([2 * idx + E, 2 * idx + F])
        if alpha_mlr is not None:
            v = np.broadcast_to(np.asarray(alpha_mlr, dtype=float), (self.batch, len(idx)))
            self.alpha_mlr[:, cols] = np.concatenate([v, v], axis=1)
        if theta_mlr is not None:
            v = np.broadcast_to(np.asarray(theta_mlr, dtype=float), (self.batch, len(idx)))
            self.theta_mlr_signed[:, cols] = np.concatenate([-v, v], axis=1)

    def _joint_indices(self, joints: list[str] | None) -> np.ndarray:
        if joints is None:
            return np.arange(self.n_joints)
        return np.array([self.circuit.joint_index(name) for name in joints], dtype=int)

    # ---------------------------------------------------------------- state

    def reset(self, seed: int = 0) -> None:
        """Back to t = 0: V = q = 0 (author's code, digest §5), no pulse, and the circuit's patterns, descending
        control, command offsets and phase-reset switches (call ``set_pattern`` etc. after ``reset``)."""
        del seed  # deterministic network; the seed is part of the module contract only
        b = self.batch
        self._load_parameters()
        self.y[...] = 0.0
        self.tick = 0
        self._pulse_amplitude = np.zeros((b, self.n_joints))
        self._pulse_remaining = np.zeros((b, self.n_joints))
        self._previous_sensory = None
        self._switched = np.zeros((b, len(self.circuit.switches)), dtype=bool)
        ns = len(self.sensor_names)
        self._sensory = np.zeros((b, ns))
        self._pf = np.zeros((b, self.n_neurons))
        self._mn = np.zeros((b, self.n_neurons))
        self.time = 0.0
        self._outputs(self._sensory)

    # ---------------------------------------------------------------- the step

    def _derivative(self, z: tuple, k: np.ndarray, k_flat: np.ndarray) -> None:
        """k = dy/dt of (4.1)-(4.2) for every cell, with the RG-RG synapses (§7.3), in place; ``z`` = a stage's
        (buffer, V as a (batch, 1, n) view, tanh part as a (batch, 2, n) view, V); ``k_flat`` = k as (batch, 2 n)."""
        buffer, V_row, tanh_part, V = z
        np.multiply(V_row, self._tanh_slope, out=tanh_part)  # (sigma_f V / A_f, V / A_f)
        np.tanh(tanh_part, out=tanh_part)
        np.dot(buffer, self._rhs, out=k_flat)  # every linear term, the fast current, the synapses
        if not self._sigma_s_shared:  # sigma_s per batch copy: sigma_s V / tau_s (4.6) in (4.2)
            k[:, 1] += self._sigma_s_over_tau_s * V
        if self._split:  # (4.8): sigma_in below E_s, sigma_out above, instead of sigma_s
            sigma = np.where(V < self.E_s, self.sigma_in, self.sigma_out)
            k[:, 1] += (sigma - self.sigma_s) * (V - self.E_s) / self.tau_s
        if self._has_constant:
            k += self._constant  # (i_ext / tau_m, -sigma_s E_s / tau_s)

    def _rk4(self, h: float) -> None:
        """One classic RK4 step of length h (s) of the whole network, in place on ``self.y``:
        y += h/6 (k1 + 2 k2 + 2 k3 + k4), k1 = f(y), k2 = f(y + h/2 k1), k3 = f(y + h/2 k2), k4 = f(y + h k3)."""
        y, ys = self.y, self._ys
        (k1, f1), (k2, f2), (k3, f3), (k4, f4) = self._k
        self._derivative(self._stage0, k1, f1)
        np.multiply(k1, 0.5 * h, out=ys)
        ys += y
        self._derivative(self._stage, k2, f2)
        np.multiply(k2, 0.5 * h, out=ys)
        ys += y
        self._derivative(self._stage, k3, f3)
        np.multiply(k3, h, out=ys)
        ys += y
        self._derivative(self._stage, k4, f4)
        k2 += k3
        k2 *= 2.0
        k1 += k2
        k1 += k4
        k1 *= h / 6.0
        y += k1

    def advance(self, sensors=None, control_dt: float = 0.01, substeps: int = 10) -> np.ndarray:
        """One control tick: sample the sensors, apply triggers and pulses, integrate ``control_dt`` s in
        ``substeps`` RK4 steps (h = 1 ms by default), then compute PF and MN.

        ``sensors``: raw input values in the order of ``circuit.inputs`` (angles in rad, forces in N, ...),
        shape (inputs,) or (batch, inputs); None = all zero. Returns MN activities, (joints, 2) = [MN_E, MN_F]
        per joint ((batch, joints, 2) when batched)."""
        b = self.batch
        shape = (b, len(self.circuit.inputs))
        phi = np.zeros(shape) if sensors is None else np.broadcast_to(np.asarray(sensors, dtype=float), shape)
        rho = sensory_neuron(phi[:, self._sensor_input], self._sensor_alpha, self._sensor_theta)  # (4.13)
        self._phase_resets(rho)
        self._switches(phi)
        self._constant[:, 0] = self._injected_current() / self.tau_m
        self._constant[:, 1] = self._slow_constant
        self._has_constant = bool(np.any(self._constant))
        h = control_dt / substeps
        for _ in range(substeps):
            self._rk4(h)
        self.tick += 1
        self.time = self.tick * control_dt
        self._pulse_remaining -= control_dt
        self._outputs(rho)
        return self.motor_neuron

    def _outputs(self, rho: np.ndarray) -> None:
        """PF (4.9)-(4.10) and MN (4.11)-(4.12) from V at the end of the tick and the sampled sensory neurons."""
        self._sensory = rho
        V = self.y[:, 0]
        I_pf = averaged_input(self._w_rg2pf, V, self._w_pf, rho, self._n_pf)  # (4.10) L1110
        self._pf = pattern_formation(I_pf, self.pf_alpha, self.alpha_mlr, self.pf_theta, self.theta_mlr_signed)  # (4.9)
        I_mn = averaged_input(self._w_pf2mn, self._pf, self._w_mn, rho, self._n_mn)  # (4.12) L1125
        self._mn = motor_neuron(I_mn, self.mn_alpha, self.mn_theta)  # (4.11) L1123

    def _injected_current(self) -> np.ndarray:
        """i_ext per neuron for this tick: scheduled kicks and pulses, +amplitude into RG-F, -amplitude into RG-E."""
        per_joint = np.where(self._pulse_remaining > 1e-9, self._pulse_amplitude, 0.0)
        t = self.time
        for joints, start, duration, amplitude in self._kicks:
            if start - 1e-9 <= t < start + duration - 1e-9:
                per_joint[:, joints] += amplitude
        i_ext = np.empty((self.batch, self.n_neurons))
        i_ext[:, E::2] = -per_joint
        i_ext[:, F::2] = per_joint
        return i_ext

    def _phase_resets(self, rho: np.ndarray) -> None:
        """§7.10: a sensory neuron rising through its threshold starts a pulse into its joint's RG."""
        previous, self._previous_sensory = self._previous_sensory, rho
        if previous is None:
            return
        if not self._resets or not self.phase_reset_enabled.any():
            return
        sensor, joint, amplitude, duration, threshold = self._reset_arrays
        rising = (previous[:, sensor] < threshold) & (rho[:, sensor] >= threshold) & self.phase_reset_enabled
        for copy, n in zip(*np.nonzero(rising), strict=True):
            self._pulse_amplitude[copy, joint[n]] = amplitude[n]
            self._pulse_remaining[copy, joint[n]] = duration[n]

    def _switches(self, phi: np.ndarray) -> None:
        for n, s in enumerate(self.circuit.switches):
            if s.at is not None:
                due = np.full(self.batch, s.at - 1e-9 <= self.time)
            else:
                due = phi[:, self.circuit.inputs.index(s.input)] > s.above
            due &= ~self._switched[:, n]
            if due.any():
                self._switched[due, n] = True
                patterns = {name: (rg.sigma_s, rg.sigma_f) for name, rg in s.joints.items()}
                self.switch_pattern(patterns, kick=s.kick, duration=s.kick_duration, sensors=phi, where=due)

    def switch_pattern(
        self,
        patterns: dict[str, tuple[float, float]],
        kick: float = 1.0,
        duration: float = 0.2,
        sensors=None,
        where=None,
    ) -> None:
        """§7.11 (the author's later method, digest §5): set each named joint's (sigma_s, sigma_f), reset its
        V = q = 0, set theta_0 := its measured angle (position command, if the joint names ``angle_input``
        and ``sensors`` are given), and inject +kick into RG-F / -kick into RG-E for ``duration`` s.
        ``where``: boolean mask of the batch copies to switch (default all)."""
        mask = np.ones(self.batch, dtype=bool) if where is None else np.asarray(where, dtype=bool)
        for name, (sigma_s, sigma_f) in patterns.items():
            j = self.circuit.joint_index(name)
            cols = [2 * j + E, 2 * j + F]
            for array, value in ((self.sigma_s, sigma_s), (self.sigma_f, sigma_f)):
                array[np.ix_(mask, cols)] = value
            self.sigma_in[np.ix_(mask, cols)] = sigma_s
            self.sigma_out[np.ix_(mask, cols)] = sigma_s
            self.y[np.ix_(mask, [0, 1], cols)] = 0.0
            self._pulse_amplitude[mask, j] = kick
            self._pulse_remaining[mask, j] = duration
            source = self._angle_input[j]
            if sensors is not None and source is not None and self.circuit.command == "position":
                phi = np.broadcast_to(sensors, (self.batch, len(self.circuit.inputs)))
                self.theta0[mask, j] = phi[mask, source]
        self._split = bool(np.any(self.sigma_in != self.sigma_s) or np.any(self.sigma_out != self.sigma_s))
        self._update_coefficients()

    # ---------------------------------------------------------------- outputs

    def command(self) -> np.ndarray:
        """The joint commands, (joints,) or (batch, joints).

        voltage: (3.6) L874 V = M (G_E U_E + G_F U_F), with G_E = +1, G_F = -1 (as the reflexive controller of
        ch. 3) and M = the joint's gain, in V; position: theta_0 + G (MN_E - MN_F) in rad (author's code, digest
        §5 and §7.8)."""
        mn = self._mn
        drive = self.gain * (mn[:, E::2] - mn[:, F::2])
        out = drive if self.circuit.command == "voltage" else self.theta0 + drive
        return out if self.batched else out[0]

    def _per_joint(self, x: np.ndarray) -> np.ndarray:
        out = x.reshape(self.batch, self.n_joints, 2)
        return out if self.batched else out[0]

    @property
    def membrane_potential(self) -> np.ndarray:
        """RG V per joint, (joints, 2) = [E, F] ((batch, joints, 2) when batched)."""
        return self._per_joint(self.y[:, 0].copy())

    @property
    def slow_current(self) -> np.ndarray:
        """RG q per joint, [E, F]."""
        return self._per_joint(self.y[:, 1].copy())

    @property
    def pattern_formation(self) -> np.ndarray:
        """PF activity per joint, [E, F], in [0, 1]."""
        return self._per_joint(self._pf.copy())

    @property
    def motor_neuron(self) -> np.ndarray:
        """MN activity per joint, [E, F], in [0, 1]."""
        return self._per_joint(self._mn.copy())

    @property
    def sensory(self) -> np.ndarray:
        """Sensory neuron activities (4.13), in the order of ``circuit.sensory_neurons``."""
        return self._sensory.copy() if self.batched else self._sensory[0].copy()

    def neuron_names(self) -> list[str]:
        """Names of ``neuron_values()``: ``<joint>/<E|F>/<RG_V|RG_q|PF|MN>`` then ``sensory/<name>``."""
        kinds = ("RG_V", "RG_q", "PF", "MN")
        names = [f"{j}/{side}/{kind}" for kind in kinds for j in self.joint_names for side in "EF"]
        return names + [f"sensory/{s}" for s in self.sensor_names]

    def neuron_values(self) -> np.ndarray:
        """Every neuron's activity as one flat vector (per batch copy when batched), for recording."""
        out = np.concatenate([self.y[:, 0], self.y[:, 1], self._pf, self._mn, self._sensory], axis=1)
        return out if self.batched else out[0]
