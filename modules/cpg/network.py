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
  tanh output carries the intra-joint RG-E <-> RG-F synapse of Table 4.1 (-1). The PF reads V itself
  (``pf_input: potential``, the author's code) or that bounded output (``pf_input: bounded``, an input of order 1 as
  the thesis's Fig. 4.6 suggests; issue 23).
- §7.5: n in (4.10)/(4.12) = the number of sensory synapses declared on that neuron, zero weights
  included.
- §7.6: theta_MLR enters with opposite signs: theta_eff = theta - theta_MLR on PF-E and theta + theta_MLR
  on PF-F, so +0.5 is extensor domination (L1160).
- §7.7: alpha_MLR literally as in (4.9): the PF slope is alpha * alpha_MLR.
The logic around these equations, one seam per module, each a part (a mixin) of ``CPGNetwork`` that builds its own
state in ``_build_*`` and restarts it per trial in ``_reset_*``:

- ``trial_start.py``: a trial's first tick (start from the pose, start on a slope, L1737) and the start ramp;
- ``gains.py``: ch. 5's learnt gains in groups (w1 pitch, w2 roll, L1631), about the calibrated gait's drive at rest;
- ``phase_reset.py``: phase resetting (§7.10, L1270-1282);
- ``switching.py``: pattern switching (§7.11, L1311, L1437);
- ``terrain.py``: switching parameters when the terrain changes (§5.8, L1759-1766; §7.17), and detectors watched;
- ``adaptation.py``: each ankle's centre following the sensed slope (L1417, L1764; issue 29);
- ``posture.py``: the torso held near an angle (L1764, §7.18).

Nothing of these costs a tick when off: one test each in ``advance``.

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

from .adaptation import AnkleAdaptation
from .circuit import Circuit
from .equations import (  # noqa: F401 - the cell equations, importable from here as before
    E,
    F,
    _logistic,
    averaged_input,
    fast_current,
    motor_neuron,
    pattern_formation,
    rhythm_generator,
    sensory_neuron,
    sigmoid,
    slow_steady_state,
)
from .events import PhaseResetEvent, ResetTrigger, SwitchEvent  # noqa: F401 - importable from here as before
from .gains import GainGroups
from .phase_reset import PhaseResetting
from .posture import Posture
from .switching import PatternSwitching
from .terrain import TerrainSwitching
from .trial_start import TrialStart

#: ``np.dot``'s C function without its ``__array_function__`` dispatch (a Python call per use, about 0.3 us: 50 uses per
#: control tick on the hot path); the same function, so the same numbers, bit for bit
#: (tests/bodies/test_humanoid_speed.py)
_dot = getattr(np.dot, "_implementation", np.dot)

TARGETS = ("PF_E", "PF_F", "MN_E", "MN_F")


class CPGNetwork(TrialStart, GainGroups, PhaseResetting, PatternSwitching, TerrainSwitching, AnkleAdaptation, Posture):
    """A circuit's MLMP-CPG, ``batch`` independent copies of it integrated together.

    ``batch=None`` (the default) is one network whose accessors return arrays without the batch axis.
    Per-copy parameters (``set_pattern``, ``set_descending``) may differ between copies."""

    #: how ``advance`` integrates: "numpy" (``_integrate``, the default) or "numba" (``compiled.py``, the same RK4
    #: compiled, the ``fast`` extra; within 1e-9 of numpy's commands, issue 31)
    KERNELS = ("numpy", "numba")

    def __init__(self, circuit: Circuit, batch: int | None = None, kernel: str = "numpy") -> None:
        if kernel not in self.KERNELS:
            raise ValueError(f"kernel: expected one of {list(self.KERNELS)}; got {kernel!r}")
        self._rk4_compiled = None
        if kernel == "numba":
            try:
                from .compiled import rk4_steps
            except ImportError as exc:
                raise ValueError(
                    f"kernel 'numba': numba is not installed ({exc}); pip install -e '.[fast]', or kernel 'numpy'"
                ) from None
            from .compiled import layers

            self._rk4_compiled, self._layers_compiled = rk4_steps, layers
        self.kernel = kernel
        self.circuit = circuit
        self.batched = batch is not None
        self.batch = batch or 1
        self.joint_names = [j.name for j in circuit.joints]
        nj = len(circuit.joints)
        self.n_joints, self.n_neurons = nj, 2 * nj
        cell = circuit.cell
        self.tau_m, self.tau_s, self.A_f, self.E_s = cell.tau_m, cell.tau_s, cell.A_f, cell.E_s
        self._build_synapses(circuit)
        # scheduled kicks (injected currents, §7.1)
        self._kicks = [
            (np.array([circuit.joint_index(name) for name in k.joints]), k.start, k.duration, k.amplitude)
            for k in circuit.kicks
        ]
        self._build_rk4_buffers()

        # the logic around the equations, one seam each (see their modules)
        self._build_gains(circuit)
        self._build_posture(circuit)
        self._build_ankles(circuit)
        self._build_phase_resets(circuit)
        self._build_switches(circuit)
        self._build_trial_start(circuit)
        self.reset(0)

    def _build_synapses(self, circuit: Circuit) -> None:
        """The circuit's synapses as the tick uses them: the RG -> RG couplings (§7.3, Table 4.1), the sensory neurons
        (4.13) and their synaptic tables into PF (4.10) and MN (4.12), the RG -> PF -> MN weights."""
        n = self.n_neurons
        # RG -> RG synapses through tanh(V / A_f) (§7.3): W[target, source]; a switch may silence some (reset restores)
        W = np.zeros((n, n))
        for j, joint in enumerate(circuit.joints):
            W[2 * j + F, 2 * j + E] += joint.rg_mutual  # Table 4.1: RG-E -> RG-F
            W[2 * j + E, 2 * j + F] += joint.rg_mutual  # Table 4.1: RG-F -> RG-E
        for c in circuit.couplings:
            W[circuit.neuron_index(c.target), circuit.neuron_index(c.source)] += c.weight
        self._circuit_coupling = W

        # sensory neurons (4.13) and the synaptic tables: PF and MN input weights per neuron
        self.sensor_names = [s.name for s in circuit.sensory_neurons]
        self._sensor_input = np.array([circuit.inputs.index(s.input) for s in circuit.sensory_neurons], dtype=int)
        self._sensor_alpha = np.array([s.alpha for s in circuit.sensory_neurons])
        self._sensor_theta = np.array([s.theta for s in circuit.sensory_neurons])
        self._sensor_theta_file = self._sensor_theta.copy()  # the file's; posture.relative_sensors move some
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
        self._w_sensory = np.concatenate([self._w_pf, self._w_mn], axis=1)  # both tables, one dot per tick
        self._pf_divisor, self._mn_divisor = self._n_pf + 1, self._n_mn + 1  # (n + 1) of (4.10), (4.12)
        self._sensor_half_alpha = 0.5 * self._sensor_alpha  # halved for _logistic
        self._w_rg2pf = np.repeat([j.w_rg2pf for j in circuit.joints], 2)
        self._pf_bounded = circuit.pf_input == "bounded"  # the PF reads tanh(V / A_f), not V (circuit.py)
        self._w_pf2mn = np.repeat([j.w_pf2mn for j in circuit.joints], 2)

        self.mn_alpha, self.mn_theta = circuit.motor_neuron.alpha, circuit.motor_neuron.theta
        self._mn_half_slope = 0.5 * self.mn_alpha  # halved for _logistic

    def _build_rk4_buffers(self) -> None:
        """The hot path's arrays, allocated once (``_integrate``): a stage's input z = [V, q, tanh(sigma_f V / A_f),
        tanh(V / A_f)] per copy; the state y = [V, q] is the first half of stage 1's buffer, so stage 1 reads it in
        place."""
        b, n = self.batch, self.n_neurons
        self._phi = np.zeros((b, len(self.circuit.inputs)))
        self._z0, self._zs = np.zeros((b, 4 * n)), np.zeros((b, 4 * n))
        self.y = self._z0[:, : 2 * n].reshape(b, 2, n)  # V = y[:, 0], q = y[:, 1]
        assert np.shares_memory(self.y, self._z0)

        def stage(z: np.ndarray) -> tuple:  # (z, V, the fast tanh part, the synaptic tanh part, both tanh parts)
            return z, z[:, :n], z[:, 2 * n : 3 * n], z[:, 3 * n :], z[:, 2 * n :]

        self._stage0, self._stage = stage(self._z0), stage(self._zs)
        self._increments = np.zeros((4, b, 2 * n))  # c_i k_i of the four stages, c = (h/2, h/2, h, h)
        self._combined = np.zeros(b * 2 * n)
        # y(t + h) = y + h/6 (k1 + 2 k2 + 2 k3 + k4) = y + (h/2 k1)/3 + 2 (h/2 k2)/3 + (h k3)/3 + (h k4)/6
        self._rk4_weights = np.array([1.0 / 3.0, 2.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0])
        self._no_constant = np.zeros((b, 2 * n))  # the compiled kernel's constants on a tick without any

    # ---------------------------------------------------------------- parameters

    def _update_coefficients(self) -> None:
        """The right-hand side of (4.1)-(4.2) for every cell, arranged for the hot path:

        dV/dt = (-V - q + A_f tanh(sigma_f V / A_f) + sum_k w_k tanh(V_k / A_f) + i_ext) / tau_m   (4.1), (4.4), §7.3
        dq/dt = (sigma_s V - q - sigma_s E_s) / tau_s                                               (4.2), (4.6)

        A stage's input is z = [V, q, tanh(sigma_f V / A_f), tanh(V / A_f)] per copy, and dy/dt = z @ ``_rhs`` (+ the
        per-tick constants), so one derivative is two scalings, a tanh and a dot whatever the number of joints.
        ``_rhs`` rows: V, q, the fast tanh, the synaptic tanh; columns: dV/dt, dq/dt. When sigma_s differs between
        batch copies (a parameter grid), its term sigma_s V / tau_s is added elementwise instead."""
        n = self.n_neurons
        eye = np.eye(n)
        self._slope_fast = self.sigma_f / self.A_f  # tanh((sigma_f / A_f) V) (4.4)
        self._slope_synapse = np.full((self.batch, n), 1.0 / self.A_f)  # tanh(V / A_f): the presynaptic output (§7.3)
        self._sigma_s_shared = bool(np.all(self.sigma_s == self.sigma_s[0]))
        rhs = np.zeros((4 * n, 2 * n))
        rhs[:n, :n] = -eye / self.tau_m  # -V / tau_m: the leak part of fast() (4.4) in (4.1)
        rhs[n : 2 * n, :n] = -eye / self.tau_m  # -q / tau_m (4.1)
        rhs[2 * n : 3 * n, :n] = eye * (self.A_f / self.tau_m)  # +A_f tanh(sigma_f V / A_f) / tau_m (4.4) in (4.1)
        rhs[3 * n :, :n] = self.coupling.T / self.tau_m  # sum_k w_k tanh(V_k / A_f) / tau_m (§7.3)
        rhs[n : 2 * n, n:] = -eye / self.tau_s  # -q / tau_s (4.2)
        if self._sigma_s_shared:
            rhs[:n, n:] = np.diag(self.sigma_s[0]) / self.tau_s  # sigma_s V / tau_s: q_inf (4.6) in (4.2)
        self._rhs = rhs
        self._scaled = {}  # h -> (h/2 rhs, h rhs), see _integrate
        self._sigma_s_over_tau_s = self.sigma_s / self.tau_s
        self._slow_constant = -self.sigma_s * self.E_s / self.tau_s  # -sigma_s E_s / tau_s (4.6)
        self._has_slow_constant = bool(np.any(self._slow_constant))
        self._split = bool(np.any(self.sigma_in != self.sigma_s) or np.any(self.sigma_out != self.sigma_s))
        # the couplings by target cell for the compiled kernel: cell i's sources and weights at [rows[i], rows[i + 1])
        targets, sources = np.nonzero(self.coupling)
        self._coupling_rows = np.searchsorted(targets, np.arange(n + 1)).astype(np.int64)
        self._coupling_sources = sources.astype(np.int64)
        self._coupling_weights = self.coupling[targets, sources]

    def _update_pattern_formation(self) -> None:
        """The PF constants of (4.9) as the step uses them: slope alpha alpha_MLR, centre theta + theta_MLR (during
        the circuit's ``start_ramp``, alpha_MLR times the ramp's share of the way)."""
        slope = self.pf_alpha * self.alpha_mlr
        if self._ramp_share < 1.0:
            slope = slope * self._ramp_share
        self._pf_half_slope = 0.5 * slope  # halved for _logistic
        self._pf_centre = self.pf_theta + self.theta_mlr_signed

    def _load_parameters(self) -> None:
        """The circuit's per-copy parameters of the equations, (batch, neurons): RG patterns, PF constants, couplings,
        the command offsets theta_0."""
        joints, b = self.circuit.joints, self.batch

        def per_neuron(value) -> np.ndarray:
            return np.tile(np.repeat([value(j) for j in joints], 2), (b, 1))

        self.sigma_s = per_neuron(lambda j: j.rg.sigma_s)
        self.sigma_f = per_neuron(lambda j: j.rg.sigma_f)
        self.sigma_in = per_neuron(lambda j: j.rg.sigma_s if j.rg.sigma_in is None else j.rg.sigma_in)
        self.sigma_out = per_neuron(lambda j: j.rg.sigma_s if j.rg.sigma_out is None else j.rg.sigma_out)
        self.pf_alpha = per_neuron(lambda j: j.pf.alpha)
        self.pf_theta = per_neuron(lambda j: j.pf.theta)
        self.alpha_mlr = per_neuron(lambda j: j.pf.alpha_mlr)
        theta_mlr = per_neuron(lambda j: j.pf.theta_mlr)
        self.theta_mlr_signed = theta_mlr * np.tile([-1.0, 1.0], self.n_joints)  # §7.6: -theta_MLR on E, + on F
        self.theta0 = np.tile([j.theta0 for j in joints], (b, 1))
        self.coupling = self._circuit_coupling.copy()

    def set_pattern(self, sigma_s, sigma_f, joints: list[str] | None = None) -> None:
        """Set (sigma_s, sigma_f) of the named joints (all by default); each broadcast to (batch, joints)."""
        idx = self._joint_indices(joints)
        cols = np.concatenate([2 * idx + E, 2 * idx + F])
        for array, value in ((self.sigma_s, sigma_s), (self.sigma_f, sigma_f)):
            v = np.broadcast_to(np.asarray(value, dtype=float), (self.batch, len(idx)))
            array[:, cols] = np.concatenate([v, v], axis=1)
        self.sigma_in[:, cols] = self.sigma_s[:, cols]
        self.sigma_out[:, cols] = self.sigma_s[:, cols]
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
        self._update_pattern_formation()

    def inhibit_couplings(self, pairs) -> None:
        """Silence the RG-RG synapses between each pair of joints, both ways (L1311); intra-joint ones are kept.
        The coupling matrix is shared by the batch copies, so this acts on all of them (``reset`` restores it)."""
        for a, b in pairs:
            ia, ib = self.circuit.joint_index(a), self.circuit.joint_index(b)
            if ia == ib:
                continue
            for one, other in ((ia, ib), (ib, ia)):
                self.coupling[2 * one : 2 * one + 2, 2 * other : 2 * other + 2] = 0.0
        self._update_coefficients()

    def _joint_indices(self, joints: list[str] | None) -> np.ndarray:
        if joints is None:
            return np.arange(self.n_joints)
        return np.array([self.circuit.joint_index(name) for name in joints], dtype=int)

    # ---------------------------------------------------------------- state

    def reset(self, seed: int = 0) -> None:
        """Back to t = 0: V = q = 0 (author's code, digest §5), no pulse, and the circuit's patterns, descending
        control, couplings, command offsets and phase-reset switches (call ``set_pattern`` etc. after ``reset``)."""
        del seed  # deterministic network; the seed is part of the module contract only
        b = self.batch
        self._load_parameters()
        self.y[...] = 0.0
        self.tick = 0
        self._pulse_amplitude = np.zeros((b, self.n_joints))
        self._pulse_remaining = np.zeros((b, self.n_joints))
        self._pulsing = False  # some pulse has time left
        self._reset_gains()
        self._reset_posture()
        self._reset_ankles()
        self._reset_phase_resets()
        self._reset_switches()
        self._reset_trial_start()
        self._reset_terrain()
        self._update_coefficients()
        self._update_pattern_formation()
        ns = len(self.sensor_names)
        self._sensory = np.zeros((b, ns))
        self._pf = np.zeros((b, self.n_neurons))
        self._mn = np.zeros((b, self.n_neurons))
        self.time = 0.0
        self._constant = None
        self._outputs(self._sensory)

    # ---------------------------------------------------------------- the step

    def _extra_terms(self, V: np.ndarray, increment: np.ndarray, c: float) -> None:
        """Add c times the terms of dy/dt that ``_rhs`` does not hold to a stage's ``increment`` (= c k), in place:
        sigma_s V / tau_s when sigma_s differs between batch copies, the (4.8) correction, and the per-tick constants
        (i_ext / tau_m, -sigma_s E_s / tau_s)."""
        dq = increment[:, self.n_neurons :]
        if not self._sigma_s_shared:  # sigma_s per batch copy: sigma_s V / tau_s (4.6) in (4.2)
            dq += c * (self._sigma_s_over_tau_s * V)
        if self._split:  # (4.8): sigma_in below E_s, sigma_out above, instead of sigma_s
            sigma = np.where(V < self.E_s, self.sigma_in, self.sigma_out)
            dq += c * ((sigma - self.sigma_s) * (V - self.E_s) / self.tau_s)
        if self._constant is not None:
            increment += c * self._constant

    def _integrate(self, h: float, substeps: int) -> None:
        """``substeps`` classic RK4 steps of length h (s) of the whole network, in place on ``self.y``:

            y(t + h) = y + h/6 (k1 + 2 k2 + 2 k3 + k4),
            k1 = f(y), k2 = f(y + h/2 k1), k3 = f(y + h/2 k2), k4 = f(y + h k3),    f = (4.1)-(4.2) with §7.3.

        Arranged for numpy, whose cost here is per call, not per number: each stage's dot gives its increment c k
        (c = h/2, h/2, h, h) at once with ``_rhs`` scaled by c, the next stage's state is y + c k (one add), and the
        weighted sum of the four increments is one dot. A stage is then five calls and an RK4 step twenty; it
        computes the same sums as the textbook form, rounded in another order (within 1e-12 of it, see
        tests/modules/test_cpg.py)."""
        scaled = self._scaled.get(h)
        if scaled is None:
            scaled = self._scaled[h] = (0.5 * h * self._rhs, h * self._rhs)
        rhs_half, rhs_full = scaled
        multiply, tanh, dot, add = np.multiply, np.tanh, _dot, np.add
        increments = self._increments
        c1, c2, c3, c4 = increments
        all_increments = increments.reshape(4, -1)
        weights, combined = self._rk4_weights, self._combined
        y = self._z0[:, : 2 * self.n_neurons]
        y_combined = combined.reshape(y.shape)
        ys = self._zs[:, : 2 * self.n_neurons]
        z1, V1, fast1, synapse1, tanh1 = self._stage0
        z, V, fast, synapse, tanh_part = self._stage
        slope_fast, slope_synapse = self._slope_fast, self._slope_synapse
        extra = self._extra_terms if (self._constant is not None or self._split or not self._sigma_s_shared) else None
        for _ in range(substeps):
            # k1 = f(y)
            multiply(V1, slope_fast, fast1)
            multiply(V1, slope_synapse, synapse1)
            tanh(tanh1, tanh1)
            dot(z1, rhs_half, c1)
            if extra:
                extra(V1, c1, 0.5 * h)
            add(y, c1, ys)
            # k2 = f(y + h/2 k1)
            multiply(V, slope_fast, fast)
            multiply(V, slope_synapse, synapse)
            tanh(tanh_part, tanh_part)
            dot(z, rhs_half, c2)
            if extra:
                extra(V, c2, 0.5 * h)
            add(y, c2, ys)
            # k3 = f(y + h/2 k2)
            multiply(V, slope_fast, fast)
            multiply(V, slope_synapse, synapse)
            tanh(tanh_part, tanh_part)
            dot(z, rhs_full, c3)
            if extra:
                extra(V, c3, h)
            add(y, c3, ys)
            # k4 = f(y + h k3)
            multiply(V, slope_fast, fast)
            multiply(V, slope_synapse, synapse)
            tanh(tanh_part, tanh_part)
            dot(z, rhs_full, c4)
            if extra:
                extra(V, c4, h)
            # y += h/6 (k1 + 2 k2 + 2 k3 + k4)
            dot(weights, all_increments, combined)
            add(y, y_combined, y)

    def _integrate_compiled(self, h: float, substeps: int) -> None:
        """``_integrate`` in one call of the compiled kernel (``kernel="numba"``, compiled.py)."""
        constant = self._constant
        if constant is None:
            constant = self._no_constant
        self._rk4_compiled(
            self.y,
            h,
            substeps,
            float(self.tau_m),
            float(self.tau_s),
            float(self.A_f),
            float(self.E_s),
            self.sigma_s,
            self.sigma_f,
            self.sigma_in,
            self.sigma_out,
            self._split,
            self._coupling_rows,
            self._coupling_sources,
            self._coupling_weights,
            constant,
        )

    def advance(self, sensors=None, control_dt: float = 0.01, substeps: int = 10) -> np.ndarray:
        """One control tick: sample the sensors, apply triggers and pulses, integrate ``control_dt`` s in
        ``substeps`` RK4 steps (h = 1 ms by default), then compute PF and MN.

        ``sensors``: raw input values in the order of ``circuit.inputs`` (angles in rad, forces in N, ...),
        shape (inputs,) or (batch, inputs); None = all zero. Returns MN activities, (joints, 2) = [MN_E, MN_F]
        per joint ((batch, joints, 2) when batched)."""
        phi = self._phi
        if sensors is None:
            phi.fill(0.0)
        else:
            phi[...] = sensors
        rho = _logistic(self._sensor_half_alpha, phi[:, self._sensor_input] - self._sensor_theta)  # (4.13) L1133
        if self.tick == 0:
            self._first_tick(phi, rho)
        self._phase_resets(rho)
        if self._pending_switches:
            self._switches(phi, control_dt)
        if self._terrain is not None:
            self._terrain_tick(phi, control_dt)
        if self._watcher is not None:
            self._watcher.tick(phi, self.time, control_dt)
        self._constant = self._per_tick_constant()
        if self._rk4_compiled is not None:
            self._integrate_compiled(control_dt / substeps, substeps)
        else:
            self._integrate(control_dt / substeps, substeps)
        self.tick += 1
        self.time = self.tick * control_dt
        if self._pulsing:
            self._pulse_remaining -= control_dt
            self._pulsing = bool(np.any(self._pulse_remaining > 1e-9))
        if self._ramp_share < 1.0:
            self._ramp_tick()
        self._outputs(rho)
        if self._hold_at_switch:
            self._hold_commands()
        if self.ankle_adaptation:
            self.theta0[:, self._ankles.joints] += self._ankles.step(phi, rho, control_dt)
        if self.posture_gain:
            self._posture(phi, control_dt)
        return self._per_joint(self._mn)

    def _outputs(self, rho: np.ndarray) -> None:
        """PF (4.9)-(4.10) and MN (4.11)-(4.12) from V at the end of the tick and the sampled sensory neurons: the same
        as ``averaged_input``, ``pattern_formation`` and ``motor_neuron``, with the constants prepared once."""
        self._sensory = rho
        if self._rk4_compiled is not None:  # kernel numba: the same layers compiled (compiled.py ``layers``)
            self._pf, self._mn = self._layers_compiled(
                rho,
                self.y[:, 0],
                self._w_sensory,
                self._w_rg2pf,
                self._pf_bounded,
                float(self.A_f),
                self._pf_divisor,
                self._pf_half_slope,
                self._pf_centre,
                self._w_pf2mn,
                self._mn_divisor,
                float(self._mn_half_slope),
                float(self.mn_theta),
            )
            return
        rg = self.y[:, 0]
        if self._pf_bounded:  # the RG's bounded output tanh(V / A_f) (circuit ``pf_input: bounded``)
            rg = np.tanh(rg / self.A_f)
        self._pf, self._mn = self._static_layers(rho, rg)

    def _static_layers(self, rho: np.ndarray, rg) -> tuple[np.ndarray, np.ndarray]:
        """PF and MN, (batch, neurons), from what the PF reads of its RG (``rg``: V, or tanh(V / A_f)) and the sensory
        neurons ``rho``."""
        n = self.n_neurons
        drive = rho @ self._w_sensory  # sum_j w_j S_j of (4.10) in [:, :n], of (4.12) in [:, n:]
        I_pf = (self._w_rg2pf * rg + drive[:, :n]) / self._pf_divisor  # (4.10) L1110
        pf = _logistic(self._pf_half_slope, I_pf - self._pf_centre)  # (4.9) L1108
        I_mn = (self._w_pf2mn * pf + drive[:, n:]) / self._mn_divisor  # (4.12) L1125
        return pf, _logistic(self._mn_half_slope, I_mn - self.mn_theta)  # (4.11) L1123

    def _per_tick_constant(self) -> np.ndarray | None:
        """The constant terms of dy/dt over this tick, (batch, 2 neurons) = [i_ext / tau_m, -sigma_s E_s / tau_s], or
        None when both are zero. i_ext: scheduled kicks and pulses, +amplitude into RG-F, -amplitude into RG-E."""
        t = self.time
        kicks = [
            (joints, amplitude)
            for joints, start, duration, amplitude in self._kicks
            if start - 1e-9 <= t < start + duration - 1e-9
        ]
        slow = self._slow_constant
        if not (kicks or self._pulsing or self._has_slow_constant):
            return None
        per_joint = np.where(self._pulse_remaining > 1e-9, self._pulse_amplitude, 0.0)
        for joints, amplitude in kicks:
            per_joint[:, joints] += amplitude
        n = self.n_neurons
        constant = np.empty((self.batch, 2 * n))
        constant[:, E:n:2] = -per_joint / self.tau_m
        constant[:, F:n:2] = per_joint / self.tau_m
        constant[:, n:] = slow
        return constant

    # ---------------------------------------------------------------- outputs

    def command_all(self) -> np.ndarray:
        """``command`` with the batch axis always, (batch, joints)."""
        mn = self._mn
        drive = self._gain * (mn[:, E::2] - mn[:, F::2])
        return drive if self.circuit.command == "voltage" else self.theta0 + drive

    def command(self) -> np.ndarray:
        """The joint commands, (joints,) or (batch, joints).

        voltage: (3.6) L874 V = M (G_E U_E + G_F U_F), with G_E = +1, G_F = -1 (as the reflexive controller of
        ch. 3) and M = the joint's gain, in V; position: theta_0 + G (MN_E - MN_F) in rad (author's code, digest
        §5 and §7.8)."""
        mn = self._mn  # command_all's lines, not a call to it: one call less per tick (about 0.3% of a planar tick)
        drive = self._gain * (mn[:, E::2] - mn[:, F::2])
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
