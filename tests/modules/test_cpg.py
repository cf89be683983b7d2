"""The MLMP-CPG core (modules/cpg): cell equations against hand-written RK4, the pattern classes of the digest's
reference map, anti-phase locking, the energy ordering, determinism, and the circuit files' checking."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from sfl_brain.modules.cpg import CPGNetwork, apply_overrides, load_circuit, validate_circuit
from sfl_brain.modules.cpg.circuit import CIRCUITS, Kick, read_circuit_data
from sfl_brain.modules.cpg.network import averaged_input, motor_neuron, pattern_formation, sensory_neuron
from sfl_brain.modules.cpg.patterns import (
    ALMOST_OSCILLATOR,
    KICK_DURATION,
    OSCILLATOR,
    PLATEAU,
    QUIESCENT,
    classify,
    energy,
    log_energy,
    pattern_space_point,
    simulate_one_joint,
    windowed_energy,
)
from sfl_brain.scenario import ScenarioError

DT = 0.01  # control tick, s


def one_joint(**joint) -> dict:
    base = {"name": "j", "rg": {"sigma_s": 2.0, "sigma_f": 2.0}, "pf": {"alpha": 1.0}}
    return {"name": "one", "command": "position", "joints": [{**base, **joint}]}


# ------------------------------------------------------------------------------------------------
# Cell equations against one RK4 step written out by hand
# ------------------------------------------------------------------------------------------------


def hand_rk4_step(V, q, i_ext, w, sigma_s, sigma_f, tau_m, tau_s, A_f, E_s, h, sigma_in=None, sigma_out=None):
    """One classic RK4 step of two cells (E, F) coupled by w through tanh(V / A_f), scalars only."""
    sigma_in = sigma_s if sigma_in is None else sigma_in
    sigma_out = sigma_s if sigma_out is None else sigma_out

    def f(V, q):
        dV, dq = [], []
        for me, other in ((0, 1), (1, 0)):
            i = i_ext[me] + w * math.tanh(V[other] / A_f)  # §7.3
            fast = V[me] - A_f * math.tanh(sigma_f / A_f * V[me])  # (4.4)
            dV.append(-(fast + q[me] - i) / tau_m)  # (4.1)
            sigma = sigma_in if V[me] < E_s else sigma_out  # (4.8)
            dq.append((-q[me] + sigma * (V[me] - E_s)) / tau_s)  # (4.2), (4.6)
        return dV, dq

    def plus(x, k, c):
        return [a + c * b for a, b in zip(x, k, strict=True)]

    k1V, k1q = f(V, q)
    k2V, k2q = f(plus(V, k1V, h / 2), plus(q, k1q, h / 2))
    k3V, k3q = f(plus(V, k2V, h / 2), plus(q, k2q, h / 2))
    k4V, k4q = f(plus(V, k3V, h), plus(q, k3q, h))
    V1 = [V[c] + h / 6 * (k1V[c] + 2 * k2V[c] + 2 * k3V[c] + k4V[c]) for c in (0, 1)]
    q1 = [q[c] + h / 6 * (k1q[c] + 2 * k2q[c] + 2 * k3q[c] + k4q[c]) for c in (0, 1)]
    return V1, q1


@pytest.mark.parametrize("split", [False, True], ids=["(4.6)", "(4.8)"])
def test_rhythm_generator_step_equals_rk4_by_hand(split):
    rg = {"sigma_s": 1.7, "sigma_f": 2.3}
    if split:
        rg.update(sigma_in=0.9, sigma_out=2.1)
    data = one_joint(rg=rg, rg_mutual=-0.8)
    data["cell"] = {"tau_m": 0.05, "tau_s": 1.0, "A_f": 5.0, "E_s": 0.3}
    data["kicks"] = [{"joints": ["j"], "start": 0.0, "duration": 0.01, "amplitude": 0.7}]
    network = CPGNetwork(validate_circuit(data))
    V0, q0 = [0.4, -1.3], [0.25, 0.6]
    network.y[0, 0], network.y[0, 1] = V0, q0
    network.advance(None, control_dt=0.001, substeps=1)
    V1, q1 = hand_rk4_step(
        V0, q0, [-0.7, 0.7], -0.8, 1.7, 2.3, 0.05, 1.0, 5.0, 0.3, 0.001, *((0.9, 2.1) if split else ())
    )
    np.testing.assert_allclose(network.membrane_potential[0], V1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(network.slow_current[0], q1, rtol=0, atol=1e-12)


def test_coupled_joints_step_equals_rk4_by_hand():
    """Two joints, a coupling j.E -> k.F of weight 0.6 and no intra-joint synapse: k.F gets 0.6 tanh(V_jE / A_f)."""
    data = one_joint(rg_mutual=0.0)
    data["joints"].append({**data["joints"][0], "name": "k"})
    data["couplings"] = [{"source": "j.E", "target": "k.F", "weight": 0.6}]
    network = CPGNetwork(validate_circuit(data))
    network.y[0, 0] = [1.1, -0.2, 0.3, 0.5]
    network.y[0, 1] = [0.1, 0.2, -0.3, 0.4]
    network.advance(None, control_dt=0.001, substeps=1)

    def f(V, q):  # all four cells; k.F gets the synapse
        out = []
        for c in range(4):
            i = 0.6 * math.tanh(V[0] / 5.0) if c == 3 else 0.0
            out.append((-(V[c] - 5.0 * math.tanh(2.0 / 5.0 * V[c]) + q[c] - i) / 0.05, (-q[c] + 2.0 * V[c]) / 1.0))
        return [o[0] for o in out], [o[1] for o in out]

    V, q, h = [1.1, -0.2, 0.3, 0.5], [0.1, 0.2, -0.3, 0.4], 0.001
    k1 = f(V, q)
    k2 = f(
        [v + h / 2 * d for v, d in zip(V, k1[0], strict=True)], [x + h / 2 * d for x, d in zip(q, k1[1], strict=True)]
    )
    k3 = f(
        [v + h / 2 * d for v, d in zip(V, k2[0], strict=True)], [x + h / 2 * d for x, d in zip(q, k2[1], strict=True)]
    )
    k4 = f([v + h * d for v, d in zip(V, k3[0], strict=True)], [x + h * d for x, d in zip(q, k3[1], strict=True)])
    V1 = [V[c] + h / 6 * (k1[0][c] + 2 * k2[0][c] + 2 * k3[0][c] + k4[0][c]) for c in range(4)]
    np.testing.assert_allclose(network.membrane_potential.ravel(), V1, rtol=0, atol=1e-12)


def textbook_rk4(network: CPGNetwork, h: float) -> None:
    """One RK4 step as the network computed it before its hot path was rearranged for speed (issue 15), kept as the
    reference: each stage's dy/dt = z @ ``_rhs`` (+ the terms ``_rhs`` does not hold), then y + c k, one by one."""
    n = network.n_neurons

    def f(y):
        V, q = y[:, 0], y[:, 1]
        z = np.concatenate([V, q, np.tanh(V * network._slope_fast), np.tanh(V * network._slope_synapse)], axis=1)
        k = (z @ network._rhs).reshape(y.shape)
        if not network._sigma_s_shared:
            k[:, 1] += network._sigma_s_over_tau_s * V
        if network._split:
            sigma = np.where(V < network.E_s, network.sigma_in, network.sigma_out)
            k[:, 1] += (sigma - network.sigma_s) * (V - network.E_s) / network.tau_s
        if network._constant is not None:
            k += network._constant.reshape(-1, 2, n)
        return k

    y = network.y.copy()
    k1 = f(y)
    k2 = f(y + 0.5 * h * k1)
    k3 = f(y + 0.5 * h * k2)
    k4 = f(y + h * k3)
    network.y[...] = y + h / 6.0 * ((k1 + 2.0 * (k2 + k3)) + k4)


def grid_circuit() -> dict:
    """One joint with every optional term of the step: (4.8)'s split conductances, E_s != 0, a kick, a coupling."""
    data = one_joint(rg={"sigma_s": 2.0, "sigma_f": 2.0, "sigma_in": 1.5, "sigma_out": 2.5})
    data["joints"].append({**data["joints"][0], "name": "k"})
    data["couplings"] = [{"source": "j.E", "target": "k.F", "weight": 0.6}]
    data["cell"] = {"E_s": 0.2}
    data["kicks"] = [{"joints": ["j"], "start": 0.0, "duration": 0.08, "amplitude": 1.0}]
    return data


@pytest.mark.parametrize("name", ["planar_8link", "humanoid_nao", "author_code", "grid"])
def test_the_fast_step_stays_within_1e_12_of_the_textbook_step(name):
    """The rearranged RK4 (``CPGNetwork._integrate``) computes the same sums in another order: 3 s of each circuit
    (kicks, heel strikes, a pattern switch; a parameter grid with per-copy sigma_s and (4.8)) stay within 1e-12 of the
    step it replaced, state and commands."""
    if name == "grid":
        circuit, batch = validate_circuit(grid_circuit()), 6
    else:
        data = read_circuit_data(name)
        data["switches"] = [{"joints": {data["joints"][-1]["name"]: {"sigma_s": 1.0, "sigma_f": 0.25}}, "at": 1.5}]
        circuit, batch = validate_circuit(data), None
    fast, reference = CPGNetwork(circuit, batch), CPGNetwork(circuit, batch)
    reference._integrate = lambda h, substeps: [textbook_rk4(reference, h) for _ in range(substeps)]
    if name == "grid":
        for network in (fast, reference):
            network.set_pattern(np.linspace(0.5, 5.0, 6).reshape(-1, 1), 2.0, joints=["j"])
    rng = np.random.default_rng(11)
    sensors = rng.uniform(-0.5, 0.5, size=(300, len(circuit.inputs)))
    if "heel_l" in circuit.inputs:
        sensors[:, circuit.inputs.index("heel_l")] = np.where(np.arange(300) % 60 < 30, 150.0, 0.0)
    for values in sensors:
        fast.advance(values)
        reference.advance(values)
        np.testing.assert_allclose(fast.y, reference.y, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fast.command(), reference.command(), rtol=0, atol=1e-12)
    assert np.ptp(reference.y[:, 0]) > 1.0  # it moved


def test_pattern_formation_motor_and_sensory_neurons_by_hand():
    """(4.9)-(4.13) with the (n + 1) averaging, theta_MLR with opposite signs on E and F (§7.6)."""
    data = one_joint(
        pf={"alpha": 2.0, "theta": 0.1, "alpha_mlr": 0.5, "theta_mlr": 0.3},
        synapses={"S": {"PF_E": 0.2, "MN_F": -0.4}, "T": {"PF_E": 0.0, "MN_E": 0.9}},
    )
    data["inputs"] = ["a", "b"]
    data["sensory_neurons"] = [
        {"name": "S", "input": "a", "alpha": 3.0, "theta": 0.2},
        {"name": "T", "input": "b", "alpha": -2.0, "theta": 0.5},
    ]
    network = CPGNetwork(validate_circuit(data))
    network.advance(np.array([0.7, -0.1]), control_dt=0.001, substeps=1)  # V stays 0 (no kick) ...
    network.y[0, 0] = [1.5, -2.5]  # ... so set it and recompute the static layers
    network._outputs(network._sensory)
    S = 1.0 / (1.0 + math.exp(3.0 * (0.2 - 0.7)))  # (4.13)
    T = 1.0 / (1.0 + math.exp(-2.0 * (0.5 - (-0.1))))
    I_pf_E = (1.5 + 0.2 * S + 0.0 * T) / 3  # (4.10): two synapses declared on PF-E, zero weight included (§7.5)
    I_pf_F = -2.5 / 1
    PF_E = 1.0 / (1.0 + math.exp(2.0 * 0.5 * ((0.1 - 0.3) - I_pf_E)))  # (4.9), theta_eff,E = theta - theta_MLR
    PF_F = 1.0 / (1.0 + math.exp(2.0 * 0.5 * ((0.1 + 0.3) - I_pf_F)))  # theta_eff,F = theta + theta_MLR
    MN_E = 1.0 / (1.0 + math.exp(5.0 * (0.5 - (PF_E + 0.9 * T) / 2)))  # (4.11), (4.12)
    MN_F = 1.0 / (1.0 + math.exp(5.0 * (0.5 - (PF_F - 0.4 * S) / 2)))
    np.testing.assert_allclose(network.sensory, [S, T], rtol=0, atol=1e-12)
    np.testing.assert_allclose(network.pattern_formation[0], [PF_E, PF_F], rtol=0, atol=1e-12)
    np.testing.assert_allclose(network.motor_neuron[0], [MN_E, MN_F], rtol=0, atol=1e-12)
    assert network.command()[0] == pytest.approx(1.0 * (MN_E - MN_F), abs=1e-12)


@pytest.mark.parametrize("pf_input", ["potential", "bounded"])
def test_the_static_layers_are_the_readable_equations_exactly(pf_input):
    """The tick computes PF, MN and the sensory neurons with prepared constants (halved slopes, one dot for both
    synaptic tables); ``sensory_neuron``, ``averaged_input``, ``pattern_formation`` and ``motor_neuron`` (the equations
    as written) give the same bits, with the PF fed V or tanh(V / A_f) (the circuit's ``pf_input``)."""
    network = CPGNetwork(apply_overrides(read_circuit_data("planar_8link"), {"pf_input": pf_input}))
    network.set_descending(alpha_mlr=0.7, theta_mlr=0.2, joints=["ankle_l"])
    rng = np.random.default_rng(5)
    for _ in range(30):
        phi = rng.uniform(-0.5, 0.5, len(network.circuit.inputs)) * np.where(
            rng.random(len(network.circuit.inputs)) < 0.3, 300.0, 1.0
        )
        network.advance(phi)
    rho = sensory_neuron(phi[network._sensor_input], network._sensor_alpha, network._sensor_theta)
    signed = network.theta_mlr_signed
    V = network.y[:, 0]
    rg_output = np.tanh(V / network.A_f) if pf_input == "bounded" else V  # what the PF reads of its RG (4.10)
    pf = pattern_formation(
        averaged_input(network._w_rg2pf, rg_output, network._w_pf, rho, network._n_pf),
        network.pf_alpha,
        network.alpha_mlr,
        network.pf_theta,
        signed,
    )
    mn = motor_neuron(averaged_input(network._w_pf2mn, pf, network._w_mn, rho, network._n_mn), 5.0, 0.5)
    np.testing.assert_array_equal(network.sensory, rho)
    np.testing.assert_array_equal(network._pf, pf)
    np.testing.assert_array_equal(network._mn, mn)


# ------------------------------------------------------------------------------------------------
# Patterns
# ------------------------------------------------------------------------------------------------

# (sigma_s, sigma_f) -> class, from the digest's numerical reference map (CPG-HUMANOID.md §1.7)
DOCUMENTED = {
    (0.0, 2.0): PLATEAU,  # sigma_s = 0, bistable
    (0.5, 3.0): PLATEAU,  # below the line sigma_s = (sigma_f - 1) / 2
    (1.0, 0.25): QUIESCENT,  # sigma_f <= 0.25
    (3.0, 0.0): QUIESCENT,
    (4.0, 0.75): ALMOST_OSCILLATOR,  # sigma_f in [0.5, 1]
    (5.0, 1.0): ALMOST_OSCILLATOR,
    (1.0, 2.0): OSCILLATOR,  # period 2.25 s
    (2.0, 2.0): OSCILLATOR,  # 1.25 s
    (5.0, 2.0): OSCILLATOR,  # 0.69 s
}
PERIODS = {(1.0, 2.0): 2.25, (2.0, 2.0): 1.25, (5.0, 2.0): 0.69}


#: the PF of the energy test: fed V with slope 1 (the planar hip's before issue 23, and sfl report's), and fed
#: tanh(V / A_f) with the planar hip's slope now (the circuit's ``pf_input: bounded``)
ENERGY_PF = {
    "V, slope 1": {"pf_input": "potential", "pf_alpha": 1.0},
    "planar hip": {
        "pf_input": load_circuit("planar_8link").pf_input,
        "pf_alpha": load_circuit("planar_8link").joints[0].pf.alpha,
    },
}


@pytest.fixture(scope="module", params=list(ENERGY_PF))
def single_cell_runs(request):
    """Every documented point as one batch: the joint's E and F uncoupled (the digest's single cell), 20 s."""
    points = list(DOCUMENTED)
    traces = simulate_one_joint(
        [p[0] for p in points], [p[1] for p in points], duration=20.0, rg_mutual=0.0, **ENERGY_PF[request.param]
    )
    return points, traces


def test_each_pattern_class_from_its_documented_parameters(single_cell_runs):
    points, traces = single_cell_runs
    for n, point in enumerate(points):
        pattern = classify(traces["V_F"][:, n], DT, KICK_DURATION)
        assert pattern.kind == DOCUMENTED[point], (point, pattern)
        if point in PERIODS:
            assert 1.0 / pattern.frequency == pytest.approx(PERIODS[point], abs=0.02), point


def test_energy_orders_plateau_quiescent_almost_oscillators_by_frequency(single_cell_runs):
    """Fig. 4.16 (L1298): plateau < quiescent < almost-oscillator < oscillators, by frequency; the joint angle
    theta = MN_E - MN_F, 10 s from the end of the kick (§7.13), the PF fed V with slope 1 and fed tanh(V / A_f) with
    the planar hip's slope (``ENERGY_PF``)."""
    points, traces = single_cell_runs
    start = int(round(KICK_DURATION / DT))
    log_e = log_energy(traces["angle"][start : start + 1001], DT)
    kinds = [classify(traces["V_F"][:, n], DT, KICK_DURATION) for n in range(len(points))]
    by_class = {k: [log_e[n] for n, p in enumerate(kinds) if p.kind == k] for k in (PLATEAU, QUIESCENT)}
    by_class[ALMOST_OSCILLATOR] = [log_e[n] for n, p in enumerate(kinds) if p.kind == ALMOST_OSCILLATOR]
    assert max(by_class[PLATEAU]) < min(by_class[QUIESCENT])
    assert max(by_class[QUIESCENT]) < min(by_class[ALMOST_OSCILLATOR])
    oscillators = sorted((p.frequency, log_e[n]) for n, p in enumerate(kinds) if p.kind == OSCILLATOR)
    assert max(by_class[ALMOST_OSCILLATOR]) < oscillators[0][1]
    assert [e for _, e in oscillators] == sorted(e for _, e in oscillators)


@pytest.mark.parametrize(
    ("pf_input", "pf_alpha", "ahead_at_plus", "ahead_at_minus"),
    [("potential", 1.0, (0.49, 0.51), (0.46, 0.48)), ("bounded", 8.6, (0.61, 0.63), (0.35, 0.37))],
)
def test_theta_mlr_dominates_when_the_pf_reads_the_bounded_rg_output(pf_input, pf_alpha, ahead_at_plus, ahead_at_minus):
    """Fig. 4.6, L1160: theta_MLR = +0.5 extensor, -0.5 flexor domination (joint (2, 2), E and F coupled by -1, the
    planar hip's PF slopes before and since issue 23). Fed V (+-5.5) the 0.5 shift hardly moves the duty cycle (MN_E
    ahead 50% / 47% of the time); fed tanh(V / A_f) it does (62% / 36%), and the joint keeps oscillating
    (docs/results/chapter4/e4_1_patterns.md)."""
    out = simulate_one_joint(
        [2.0] * 2, [2.0] * 2, duration=10.0, rg_mutual=-1.0, theta_mlr=[0.5, -0.5], pf_alpha=pf_alpha, pf_input=pf_input
    )
    e, f = out["MN_E"][400:], out["MN_F"][400:]  # after a 4-s transient
    ahead = np.mean(e > f, axis=0)
    assert ahead_at_plus[0] < ahead[0] < ahead_at_plus[1] and ahead_at_minus[0] < ahead[1] < ahead_at_minus[1], ahead
    assert np.all(np.ptp(e - f, axis=0) > 1.5)  # still oscillating: MN_E - MN_F swings over most of [-1, 1]


def test_energy_is_the_integral_of_the_squared_angular_velocity():
    t = np.arange(0, 10.0 + 1e-9, 1e-3)
    angle = 0.3 * np.sin(2 * np.pi * t)  # integral of (0.6 pi cos)^2 over 10 periods = 10 * (0.6 pi)^2 / 2
    assert energy(angle, 1e-3) == pytest.approx(10 * (0.6 * np.pi) ** 2 / 2, rel=1e-4)
    point = pattern_space_point({"hip": angle, "knee": np.zeros_like(t)}, 1e-3)
    assert point["hip"] == pytest.approx(np.log10(10 * (0.6 * np.pi) ** 2 / 2), abs=1e-4)
    assert point["knee"] == -12.0  # a still joint sits on the floor of the axis


def test_windowed_energy_is_the_energy_of_the_last_window_and_falls_to_zero_when_the_joint_stops():
    dt = 0.01
    t = np.arange(0, 6.0 + 1e-9, dt)
    angle = np.where(t < 3.0, 0.3 * np.sin(2 * np.pi * t), 0.0)  # one period a second, then still from 3 s
    track = windowed_energy(angle, dt, 1.0)
    assert np.isnan(track[:100]).all() and not np.isnan(track[100:]).any()
    assert track[250] == pytest.approx(energy(angle[150:251], dt), rel=1e-9)  # the samples of the last second
    assert track[250] == pytest.approx((0.6 * np.pi) ** 2 / 2, rel=1e-3)  # one period's integral
    assert (track[401:] == 0).all()  # a window wholly after the stop: no motion, no energy


def test_rhythm_deletion_keeps_the_phase():
    """alpha_MLR = 0 holds the joint still (PF = 1/2 on both sides) while the RG keeps its rhythm; restored, the joint
    moves exactly as if nothing had happened (L1104, L1156)."""
    circuit = load_circuit("planar_8link")
    hip = circuit.joint_index("hip_l")
    deleted, reference = CPGNetwork(circuit), CPGNetwork(circuit)
    held = []
    for tick in range(300):
        if tick == 100:
            deleted.set_descending(alpha_mlr=0.0, joints=["hip_l"])
        if tick == 200:
            deleted.set_descending(alpha_mlr=1.0, joints=["hip_l"])
        deleted.advance()
        reference.advance()
        if 100 <= tick < 200:
            held.append(deleted.command()[hip])
            np.testing.assert_array_equal(deleted.pattern_formation[hip], [0.5, 0.5])
    assert np.ptp(held) == 0.0 and np.ptp(reference.command()) > 0
    np.testing.assert_array_equal(deleted.membrane_potential, reference.membrane_potential)
    np.testing.assert_array_equal(deleted.command(), reference.command())


# ------------------------------------------------------------------------------------------------
# Circuits running
# ------------------------------------------------------------------------------------------------


def run(network: CPGNetwork, seconds: float, kinematic: bool = False) -> dict[str, np.ndarray]:
    """Run ``seconds``; with ``kinematic``, each joint's sensed angle is its last command (no body)."""
    circuit = network.circuit
    sensors = np.zeros(len(circuit.inputs))
    angle_at = [(circuit.inputs.index(j.angle_input), n) for n, j in enumerate(circuit.joints) if j.angle_input]
    V, commands = [], []
    for _ in range(int(round(seconds / DT))):
        if kinematic:
            command = network.command()
            for i, n in angle_at:
                sensors[i] = command[n]
        network.advance(sensors)
        V.append(network.membrane_potential)
        commands.append(network.command())
    return {"V": np.array(V), "command": np.array(commands)}


@pytest.mark.parametrize(
    ("name", "left", "right"), [("planar_8link", "hip_l", "hip_r"), ("humanoid_nao", "hip_pitch_l", "hip_pitch_r")]
)
def test_coupled_hips_lock_in_anti_phase_from_a_one_sided_kick(name, left, right):
    """The RG-RG couplings alone lock the hips: only the left hip is kicked (the humanoid circuit's own kicks,
    which phase its three pairs, replaced by the planar circuit's one-sided kick)."""
    circuit = load_circuit(name)
    if name == "planar_8link":
        assert [k.joints for k in circuit.kicks] == [[left]]
    else:
        circuit = circuit.model_copy(update={"kicks": [Kick(joints=[left], start=0.0, duration=0.08, amplitude=1.0)]})
    out = run(CPGNetwork(circuit), 6.0, kinematic=True)
    late = out["V"][-200:]
    l, r = late[:, circuit.joint_index(left), 1], late[:, circuit.joint_index(right), 1]
    assert np.ptp(l) > 5 and np.ptp(r) > 5  # both oscillate
    assert np.corrcoef(l, r)[0, 1] < -0.95


def test_humanoid_circuit_runs_standalone_with_finite_outputs():
    network = CPGNetwork(load_circuit("humanoid_nao"))
    assert network.n_joints == 12
    out = run(network, 3.0, kinematic=True)
    assert np.isfinite(out["V"]).all() and np.isfinite(out["command"]).all()
    assert np.isfinite(network.neuron_values()).all()
    assert len(network.neuron_names()) == network.neuron_values().size
    hip = network.circuit.joint_index("hip_pitch_l")
    assert 0.05 < np.ptp(out["command"][-100:, hip]) < 1.0  # rad: it walks-sized, not frozen, not wild


def test_author_code_circuit_gives_the_published_amplitudes():
    """Digest §5: with V = +-6.16 at (17.5, 17.5), amplitudes +-0.133 rad hip pitch, +-0.147 roll, +-0.100 knee."""
    circuit = load_circuit("author_code")
    out = run(CPGNetwork(circuit), 3.0)
    half_range = np.ptp(out["command"][-100:], axis=0) / 2
    for joint, amplitude in (("hip_pitch_l", 0.133), ("hip_roll_l", 0.147), ("knee_l", 0.100)):
        assert half_range[circuit.joint_index(joint)] == pytest.approx(amplitude, abs=0.002), joint
    assert half_range[circuit.joint_index("ankle_pitch_l")] == 0.0  # alpha = 0 freezes it, as in the code


def test_same_seed_gives_identical_arrays_and_reset_restores_the_circuit():
    data = read_circuit_data("planar_8link")
    data["switches"] = [{"joints": {"knee_l": {"sigma_s": 1.0, "sigma_f": 0.25}}, "at": 0.5}]
    circuit = validate_circuit(data)
    rng = np.random.default_rng(3)
    sensors = rng.uniform(-0.5, 0.5, size=(100, len(circuit.inputs)))
    sensors[:, circuit.inputs.index("heel_l")] = np.where(np.arange(100) % 40 < 20, 150.0, 0.0)  # heel strikes
    traces = []
    for network in (CPGNetwork(circuit), CPGNetwork(circuit)):
        for seed in (7, 7):
            network.reset(seed)
            traces.append(np.array([(network.advance(s), network.neuron_values())[1] for s in sensors]))
    for other in traces[1:]:
        np.testing.assert_array_equal(traces[0], other)


def test_phase_reset_pulses_on_heel_strike_and_can_be_switched_off():
    circuit = load_circuit("planar_8link")
    heel = circuit.inputs.index("heel_l")
    before, after = {}, {}
    for enabled in (True, False):
        network = CPGNetwork(circuit)
        # the circuit's own entries reset state (tests/modules/test_cpg_phase_reset.py)
        network.set_phase_reset("pulse")
        network.phase_reset_enabled[:] = enabled
        sensors = np.zeros(len(circuit.inputs))
        for tick in range(260):  # the circuit's resets fire after the start-up (its entries' `after`: 2 s)
            sensors[heel] = 200.0 if tick >= 250 else 0.0  # heel strike at tick 250
            network.advance(sensors)
            if tick == 249:
                before[enabled] = network.membrane_potential
        after[enabled] = network.membrane_potential
    np.testing.assert_array_equal(before[True], before[False])
    hip = circuit.joint_index("hip_l")
    assert after[True][hip, 0] - after[False][hip, 0] > 0.1  # +1 into RG-E ... (§7.10)
    assert after[True][hip, 1] - after[False][hip, 1] < -0.1  # ... and -1 into RG-F of the left hip


def knee_switch_walked_1s(switch: dict):
    """The humanoid circuit with one pattern switch of the left knee, advanced 1 s (100 ticks) with that knee's
    angle input held at 0.9 rad and every other input 0: (circuit, network, the knee's index, the sensors)."""
    data = read_circuit_data("humanoid_nao")
    data["switches"] = [switch]
    circuit = validate_circuit(data)
    network = CPGNetwork(circuit)
    sensors = np.zeros(len(circuit.inputs))
    sensors[circuit.inputs.index("knee_l")] = 0.9
    for _ in range(100):
        network.advance(sensors)
    return circuit, network, circuit.joint_index("knee_l"), sensors


def test_pattern_switch_sets_the_pattern_resets_the_cell_and_takes_the_measured_angle():
    """``theta0: angle`` (the author's 2017 scripts, digest §5; not the default): theta_0 := the measured angle."""
    switch = {
        "joints": {"knee_l": {"sigma_s": 1.0, "sigma_f": 0.25}},
        "input": "torso_pitch",
        "above": 0.3,
        "theta0": "angle",
    }
    circuit, network, knee, sensors = knee_switch_walked_1s(switch)
    assert network.sigma_s[0, 2 * knee] == 5.0
    sensors[circuit.inputs.index("torso_pitch")] = 0.5  # the push detector fires
    network.advance(sensors, control_dt=0.001, substeps=1)
    assert network.sigma_s[0, 2 * knee] == 1.0 and network.sigma_f[0, 2 * knee + 1] == 0.25
    assert network.theta0[0, knee] == 0.9
    V = network.membrane_potential[knee]
    assert -0.03 < V[0] < 0 < V[1] < 0.03  # from V = 0, one 1-ms step of the +1 (F) / -1 (E) kick
    theta0 = network.theta0.copy()
    for _ in range(50):
        network.advance(sensors)  # fires once only
    np.testing.assert_array_equal(network.theta0, theta0)


def test_a_continuous_switch_keeps_the_command_at_the_measured_angle_where_theta0_angle_jumps():
    """``theta0: continuous`` (the default) keeps the command at the measured angle; ``angle`` (the rule of the author's
    2017 scripts, whose circuit has no reflexes; digest §5) makes it jump by the offset the reflexes held."""
    commands = {}
    for theta0 in ("angle", "continuous"):
        switch = {"joints": {"knee_l": {"sigma_s": 5.0, "sigma_f": 17.5}}, "at": 1.0, "theta0": theta0}
        _, network, knee, sensors = knee_switch_walked_1s(switch)
        before = network.command()[knee]
        network.advance(sensors)  # the switch's tick
        commands[theta0] = (before, network.command()[knee], network.theta0[0, knee])
    before, after, theta0 = commands["angle"]
    assert theta0 == 0.9 and abs(after - 0.9) > 0.1  # theta_0 := angle: the reflexes' offset makes the command jump
    before_c, after_c, theta0_c = commands["continuous"]
    assert before_c == before and after_c == pytest.approx(0.9, abs=1e-12) and theta0_c != 0.9


# ------------------------------------------------------------------------------------------------
# Circuit files: checking and overriding
# ------------------------------------------------------------------------------------------------


def test_every_shipped_circuit_loads():
    names = sorted(p.stem for p in CIRCUITS.glob("*.yaml"))
    assert names == ["author_code", "humanoid_nao", "planar_8link", "planar_8link_servo"]
    joints = {name: len(load_circuit(name).joints) for name in names}
    assert joints == {"author_code": 12, "humanoid_nao": 12, "planar_8link": 7, "planar_8link_servo": 7}


def write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_bad_key_fails_with_its_key_path(tmp_path):
    data = read_circuit_data("planar_8link")
    data["joints"][2]["pf"]["alpah"] = data["joints"][2]["pf"].pop("alpha")
    path = write(tmp_path, data)
    with pytest.raises(ScenarioError) as err:
        load_circuit(path)
    assert str(err.value) == (
        f"{path}: joints.2.pf.alpha: required key is missing\n"
        f"{path}: joints.2.pf.alpah: unknown key; expected one of ['alpha', 'alpha_mlr', 'theta', 'theta_mlr'] "
        "(did you mean `alpha`?)"
    )


def test_a_bad_reference_names_both_ends(tmp_path):
    data = read_circuit_data("planar_8link")
    data["couplings"][0]["source"] = "hipl.E"
    data["joints"][0]["synapses"]["ES_hipl"] = data["joints"][0]["synapses"].pop("ES_hip_l")
    with pytest.raises(ScenarioError) as err:
        validate_circuit(data, "planar.yaml")
    lines = str(err.value).splitlines()
    assert lines[0].startswith("planar.yaml: joints.0.synapses.ES_hipl: expected one of the sensory neurons [")
    assert lines[0].endswith("; got 'ES_hipl' (did you mean `ES_hip_l`?)")
    assert lines[1].startswith("planar.yaml: couplings.0.source: expected one of the RG neurons ['hip_l.E', ")
    assert lines[1].endswith("; got 'hipl.E' (did you mean `hip_l.E`?)")


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("2.0", "joints.0.rg.sigma_s: expected a number; got '2.0' (did you mean `2.0`?)"),
        (True, "joints.0.rg.sigma_s: expected a number; got true"),
        (float("nan"), "joints.0.rg.sigma_s: expected a finite number; got .nan"),
        (float("inf"), "joints.0.rg.sigma_s: expected a finite number; got .inf"),
        (-1.0, "joints.0.rg.sigma_s: input should be greater than or equal to 0; got -1.0"),
    ],
)
def test_circuit_numbers_are_strict_and_finite(value, message):
    with pytest.raises(ScenarioError) as err:
        apply_overrides(read_circuit_data("planar_8link"), {"joints.0.rg.sigma_s": value}, file="c.yaml")
    assert str(err.value) == f"c.yaml: {message}"


def test_overrides_set_a_weight_by_dotted_path_and_revalidate():
    data = read_circuit_data("planar_8link")
    circuit = apply_overrides(data, {"couplings.0.weight": 1.5, "phase_resets.1.enabled": False})
    assert circuit.couplings[0].weight == 1.5 and circuit.phase_resets[1].enabled is False
    assert data["couplings"][0]["weight"] == 1.0  # the input is not changed
    network = CPGNetwork(circuit)
    assert network.coupling[circuit.neuron_index("hip_r.F"), circuit.neuron_index("hip_l.E")] == 1.5
    with pytest.raises(ScenarioError) as err:
        apply_overrides(data, {"couplings.99.weight": 1.5, "joints.0.rgg.sigma_s": 1.0}, file="c.yaml")
    assert str(err.value) == (
        "c.yaml: couplings.99: expected an index below 12; got '99'\n"
        "c.yaml: joints.0.rgg: no such key; expected one of "
        "['angle_input', 'gain', 'name', 'pf', 'rg', 'synapses'] (did you mean `rg`?)"
    )


def test_nested_overrides_merge_key_by_key():
    """The nested form ``sfl --set`` builds is the dotted one; a mapping merges into the one in the file."""
    data = read_circuit_data("planar_8link")
    nested = apply_overrides(
        data, {"joints": {"2": {"rg": {"sigma_s": 3.0}, "synapses": {"ES_knee_l": {"MN_E": -0.2}}}}}
    )
    dotted = apply_overrides(data, {"joints.2.rg.sigma_s": 3.0, "joints.2.synapses.ES_knee_l.MN_E": -0.2})
    assert nested == dotted
    assert nested.joints[2].rg.sigma_f == 2.0 and set(nested.joints[2].synapses) == set(data["joints"][2]["synapses"])
    with pytest.raises(ScenarioError) as err:
        apply_overrides(data, {"joints": {"9": {"gain": 1.0}}}, file="c.yaml")
    assert str(err.value) == "c.yaml: joints.9: expected an index below 7; got '9'"


def switch_problems(**switch) -> list[str]:
    data = read_circuit_data("planar_8link")
    data["switches"] = [{"joints": {"knee_l": {"sigma_s": 1.0, "sigma_f": 0.25}}, **switch}]
    with pytest.raises(ScenarioError) as err:
        validate_circuit(data, "c.yaml")
    return str(err.value).splitlines()


def test_a_switch_has_one_trigger_and_names_what_exists():
    assert switch_problems(input="pelvis") == [
        "c.yaml: switches.0: expected one of `above`, `rate_above` with `input`; got []"
    ]
    assert switch_problems(input="pelvis", above=0.1, rate_above=1.0) == [
        "c.yaml: switches.0: expected one of `above`, `rate_above` with `input`; got ['above', 'rate_above']"
    ]
    assert switch_problems(at=1.0, rate_above=1.0) == ["c.yaml: switches.0.rate_above: expected only with `input`"]
    assert switch_problems(at=1.0, joint_kicks={"hip_l": -1.0}, inhibit=[["hip_l", "kne_l"]]) == [
        "c.yaml: switches.0.joint_kicks.hip_l: expected one of the joints this switch switches ['knee_l']; got 'hip_l'",
        "c.yaml: switches.0.inhibit.0.1: expected one of the joints ['hip_l', 'hip_r', 'knee_l', 'knee_r', 'ankle_l', "
        "'ankle_r', 'trunk']; got 'kne_l' (did you mean `knee_l`?)",
    ]


def test_a_switch_silences_the_couplings_it_names_and_reset_restores_them():
    data = read_circuit_data("planar_8link")
    data["switches"] = [
        {
            "joints": {"knee_l": {"sigma_s": 1.0, "sigma_f": 0.25}},
            "at": 0.05,
            "joint_kicks": {"knee_l": -2.0},
            "inhibit": [["hip_l", "knee_l"]],
        }
    ]
    circuit = validate_circuit(data)
    network = CPGNetwork(circuit)
    hip, knee = (slice(2 * circuit.joint_index(j), 2 * circuit.joint_index(j) + 2) for j in ("hip_l", "knee_l"))
    before = network.coupling.copy()
    assert np.any(before[knee, hip])
    for _ in range(10):
        network.advance()
    [event] = network.switch_events
    assert (event.time, event.kicks, event.inhibited) == (pytest.approx(0.05), {"knee_l": -2.0}, (("hip_l", "knee_l"),))
    assert not np.any(network.coupling[knee, hip]) and not np.any(network.coupling[hip, knee])
    assert np.any(network.coupling[knee, knee])  # the joint's own E <-> F synapses stay (Table 4.1)
    changed = network.coupling != before
    changed[knee, hip] = changed[hip, knee] = False
    assert not changed.any()  # nothing else
    network.reset()
    np.testing.assert_array_equal(network.coupling, before)
    assert network.switch_events == []
