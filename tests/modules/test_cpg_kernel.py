"""The compiled RK4 (``kernel="numba"``, modules/cpg/compiled.py) gives the numpy step's commands within 1e-9 (issue
31).

The humanoid walks in closed loop on the numpy network, from flat onto a 5-deg ramp to the 1.5-m line, with the ankle
adaptation, the start ramp and a gradual terrain switch on the foot-slope detector (E5.3's ``up_switching``); its sensor
frames are then fed, open loop, to a controller on each kernel: every command of the walk within 1e-9 of the numpy
one's (measured: 4.7e-15 rad over 1627 ticks). A batch with every optional term of the step (per-copy sigma_s, (4.8)'s
split, E_s != 0, a kick, a coupling) agrees as closely.
"""

from __future__ import annotations

import numpy as np
import pytest

from sfl_brain.bodies.humanoid import Humanoid
from sfl_brain.body import InProcessLink
from sfl_brain.messages import ControllerReset, SensorFrame, TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams
from sfl_brain.modules.cpg import CPGNetwork
from sfl_brain.modules.cpg.circuit import validate_circuit
from sfl_brain.signals import names

from ..bodies.test_humanoid_speed import Recording
from .test_cpg import grid_circuit

pytest.importorskip("numba")

#: E5.3's uphill switching condition (scenarios/e5_switch.yaml) with the calibrated gait's gains
WALK = {
    "ankle_adaptation": "on",
    "start_ramp": 2.0,
    "terrain_switch": "gradual",
    "switch_detector": "foot_slope",
    "switch_band": 1.5,
    "switch_when": "outside",
    "next_gain_pitch": 1.2,
    "next_gain_roll": 1.1,
    "next_sigma_s": 4.0,
}


def replay(kernel: str, frames: list[np.ndarray]) -> tuple[np.ndarray, CPGController]:
    """The walk's frames, open loop, into a controller on ``kernel``: its commands, and the controller."""
    controller = CPGController(CPGParams(circuit="humanoid_nao", kernel=kernel))
    link = InProcessLink(controller)
    sensors, commands = (list(names(s)) for s in (Humanoid.SENSORS, Humanoid.COMMANDS))
    link.reset(ControllerReset(trial_id=0, seed=3, params=WALK, sensors=sensors, commands=commands, dt=0.01))
    out = [np.array(link.step(SensorFrame(trial_id=0, tick=i, values=v)).values) for i, v in enumerate(frames)]
    return np.array(out), controller


def test_the_compiled_kernel_walks_with_the_numpy_commands_within_1e_9():
    body = Humanoid(Humanoid.Params(duration=20.0))
    link = Recording(CPGController(CPGParams(circuit="humanoid_nao")))
    body.link = link
    try:
        result = body.handle(
            TrialRequest(trial_id=0, seed=3, body_params={"terrain": "1.0:0,4:5"}, controller_params=WALK, log=False)
        )
    finally:
        body.close()
    frames, walked = link.frames, np.array(link.commands)
    assert result.success and len(frames) > 1500  # the whole walk, to the line
    numpy_commands, numpy_controller = replay("numpy", frames)
    np.testing.assert_array_equal(numpy_commands, walked)  # the replay is the walk
    numba_commands, numba_controller = replay("numba", frames)
    difference = np.abs(numba_commands - numpy_commands).max()
    print(f"largest command difference over {len(frames)} ticks: {difference:.3g} rad")
    assert difference <= 1e-9
    for controller in (numpy_controller, numba_controller):
        network = controller.network
        assert network.terrain_switch_events, "the walk switched on the ramp"
        assert network.ankle_adaptation and np.any(network.ankle_centre != 0.0)
    assert (
        numba_controller.network.terrain_switch_events[0].time == numpy_controller.network.terrain_switch_events[0].time
    )


def test_the_compiled_kernel_agrees_on_a_batch_with_every_term_of_the_step():
    circuit = validate_circuit(grid_circuit())
    numpy_network, numba_network = CPGNetwork(circuit, 6), CPGNetwork(circuit, 6, kernel="numba")
    for network in (numpy_network, numba_network):
        network.set_pattern(np.linspace(0.5, 5.0, 6).reshape(-1, 1), 2.0, joints=["j"])
    sensors = np.random.default_rng(5).uniform(-0.5, 0.5, size=(500, len(circuit.inputs)))
    for values in sensors:
        numpy_network.advance(values)
        numba_network.advance(values)
        np.testing.assert_allclose(numba_network.y, numpy_network.y, rtol=0, atol=1e-9)
        np.testing.assert_allclose(numba_network.command(), numpy_network.command(), rtol=0, atol=1e-9)
    assert np.ptp(numpy_network.y[:, 0]) > 1.0  # it moved


def test_an_unknown_kernel_is_refused_with_the_choices():
    with pytest.raises(ValueError, match=r"kernel: expected one of \['numpy', 'numba'\]; got 'numbaa'"):
        CPGNetwork(validate_circuit(grid_circuit()), kernel="numbaa")


def test_the_kernels_tanh_is_the_c_librarys_within_a_quarter_of_1e_15():
    """compiled.tanh (one exp, the RK4's 1,920 tangents a tick): within 2.3e-16 of math.tanh, absolute, from tiny to
    saturated arguments of either sign; odd; NaN passes; +-inf gives +-1."""
    import math

    from sfl_brain.modules.cpg.compiled import tanh

    x = np.concatenate([np.linspace(-25.0, 25.0, 200_001), np.geomspace(1e-300, 1.0, 10_000)])
    x = np.concatenate([x, -x])
    ours = np.array([tanh(v) for v in x])
    assert np.abs(ours - np.tanh(x)).max() <= 2.3e-16
    positive = x > 0
    assert np.array_equal(ours[positive], -np.array([tanh(-v) for v in x[positive]]))  # odd
    assert math.isnan(tanh(math.nan)) and tanh(math.inf) == 1.0 and tanh(-math.inf) == -1.0
