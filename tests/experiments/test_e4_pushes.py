"""E4.3 (L1268-1282) and E4.4 (L1284-1324) on the 8-link walker: the push reaches the body, phase resetting acts on
heel contact, pattern switching sets the hip and knee patterns of Fig. 4.17 (L1311, L1317), and the survival
difference of docs/results/chapter4/e4_4_pushes.md that holds on every start and phase there (a 0.1-s push is
survived without switching; the switched posture falls).

Controller and body run in one process here, with the settings of scenarios/e4_3_pushes.yaml and e4_4_pushes.yaml (the
experiments themselves run over processes: docs/experiments/chapter4.sh).
"""

from __future__ import annotations

import numpy as np

from sfl_brain.bodies.planar_8link import PlanarWalker8
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams
from sfl_brain.modules.cpg.patterns import PATTERN_POINTS

LEGS = ["hip_l", "hip_r", "knee_l", "knee_r", "ankle_l", "ankle_r"]
SWITCH = {"hip_l": "plateau", "hip_r": "plateau", "knee_l": "quiescent", "knee_r": "quiescent"}
INHIBIT = [["hip_l", "knee_l"], ["hip_r", "knee_r"]]


class Recording(CPGController):
    """The CPG controller, keeping its inputs and its hip RG potentials per tick."""

    def configure(self, params: dict, seed: int) -> None:
        super().configure(params, seed)
        self.inputs, self.hip_potential = [], []

    def step(self, sensors: np.ndarray) -> np.ndarray:
        command = super().step(sensors)
        self.inputs.append(np.array(sensors, dtype=float))
        self.hip_potential.append(self.network.membrane_potential[:2].copy())  # hip_l, hip_r: [E, F]
        return command


def trial(seed=0, phase_reset=True, push=None, switch=None, duration=10.0, start_noise=0.02):
    """One trial as the experiment runs it: (result, controller)."""
    params = CPGParams(phase_reset=phase_reset, pattern_joints=LEGS, switch=switch or {})
    controller = Recording(params)
    body = PlanarWalker8(PlanarWalker8.Params(duration=duration, initial_knee=-0.3, start_noise=start_noise))
    body.link = InProcessLink(controller)
    body_params = {} if push is None else dict(zip(("push_force", "push_time", "push_duration"), push, strict=True))
    request = TrialRequest(trial_id=0, seed=seed, body_params=body_params, controller_params={}, log=False)
    return body.handle(request), controller


def test_the_push_speeds_the_trunk_forward_while_it_acts():
    speeds = {}
    for force in (0.0, 45.0):
        body = PlanarWalker8(PlanarWalker8.Params(duration=1.0, initial_knee=-0.3))
        body_params = {"push_force": force, "push_time": 0.05, "push_duration": 0.1} if force else {}
        body.start_trial(TrialRequest(trial_id=0, seed=0, body_params=body_params, controller_params={}, log=False))
        for _ in range(15):  # 0.15 s with the motors off: the push acts from 0.05 to 0.15 s
            body.actuate(np.zeros(len(body.COMMANDS)))
        speeds[force] = body.links[0].velocity.x  # the trunk, m/s
        assert body.pushed == bool(force)
    # 45 N x 0.1 s = 4.5 N s on a trunk jointed to the rest of the 22-kg body: well over 0.1 m/s forward (the
    # unpushed walker, motors off, sags backward from its crouch at the same time)
    assert speeds[45.0] - speeds[0.0] > 0.1


def test_start_noise_changes_the_start_by_seed_and_zero_noise_does_not():
    def first_inputs(seed, noise):
        _, controller = trial(seed=seed, duration=0.05, start_noise=noise)
        return controller.inputs[-1]

    assert not np.allclose(first_inputs(0, 0.02), first_inputs(1, 0.02))
    assert np.allclose(first_inputs(0, 0.02), first_inputs(0, 0.02))
    assert np.allclose(first_inputs(0, 0.0), first_inputs(1, 0.0))


def test_phase_resetting_first_acts_on_a_heel_strike():
    """With and without phase resetting the network runs identically until a heel's force rises through GB's 50 N
    (the circuit's reset sensor, digest §7.10): there the hip RG potentials part."""
    on, with_reset = trial(phase_reset=True, duration=3.0)
    off, without = trial(phase_reset=False, duration=3.0)
    assert on.metrics["steps"] >= 2 and off.metrics["steps"] >= 2
    a, b = np.array(with_reset.hip_potential), np.array(without.hip_potential)
    n = min(len(a), len(b))
    parted = np.flatnonzero(np.abs(a[:n] - b[:n]).max(axis=(1, 2)) > 1e-9)
    assert len(parted), "phase resetting never changed the hip rhythm"
    k = int(parted[0])
    names = list(with_reset.circuit.inputs)
    heels = np.array(with_reset.inputs)[:, [names.index("heel_l"), names.index("heel_r")]]
    assert k >= 1 and ((heels[k] >= 50.0) & (heels[k - 1] < 50.0)).any()


def test_a_pattern_switch_sets_hip_plateau_knee_quiescent_and_silences_hip_knee_couplings():
    switch = {"trigger": "time", "at": 1.0, "joints": SWITCH, "inhibit": INHIBIT}
    _, controller = trial(switch=switch, duration=1.5)
    network, circuit = controller.network, controller.circuit
    (event,) = network.switch_events
    assert abs(event.time - 1.0) < 0.011
    for name, kind in {**SWITCH, "ankle_l": "oscillator", "ankle_r": "oscillator"}.items():
        j = circuit.joint_index(name)
        assert (network.sigma_s[0, 2 * j], network.sigma_f[0, 2 * j]) == PATTERN_POINTS[kind], name
    hip, knee, ankle = (circuit.joint_index(n) for n in ("hip_l", "knee_l", "ankle_l"))
    assert not network.coupling[2 * knee : 2 * knee + 2, 2 * hip : 2 * hip + 2].any()  # L1311: inhibited
    assert network.coupling[2 * ankle : 2 * ankle + 2, 2 * hip : 2 * hip + 2].any()  # ankle-hip kept


def test_a_45_n_push_for_0_1_s_is_survived_without_switching_and_fells_the_switched_walker():
    """Our E4.4 result (against the thesis's Fig. 4.18), on every seed and phase of the results page: here seed 0 at
    phase 0, the push's onset at the left heel strike of 4.77 s (the script's gait measure, phase resetting on)."""
    push = (45.0, 4.77, 0.1)
    plain, _ = trial(push=push)
    assert not plain.metrics["fell"] and plain.metrics["pushed"]
    switch = {"trigger": "time", "at": push[1], "joints": SWITCH, "inhibit": INHIBIT}
    switched, _ = trial(push=push, switch=switch)
    assert switched.metrics["fell"] and switched.metrics["fell_at"] < push[1] + 2.0
