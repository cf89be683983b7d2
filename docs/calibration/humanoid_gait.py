"""The humanoid's default CPG gait: where the gains and offsets of ``humanoid_nao.yaml`` come from; does it walk.

    python docs/calibration/humanoid_gait.py [--calibrate] [--walk 10] [--noise 0.02] [--alpha-mlr 1 ...]
                                             [--set KEY=VALUE ...]

The circuit ``modules/cpg/circuits/humanoid_nao.yaml`` sets each joint's command theta_0 + G (MN_E - MN_F) (digest
§5, §7.8). Neither G nor theta_0 is in the thesis; they are computed here from two conditions:

- **theta_0**: at t = 0 (every RG at rest, V = q = 0, no kick yet) the command is the body's standing pose
  (``bodies/humanoid_table.py`` ``STANDING``), read on the body's first sensor frame (joints at the standing pose,
  feet unloaded 0.5 mm above the ground). The articular reflex (ES/FS -> MN, -0.4, Table 4.1) and the knee's
  stretch reflex (AS -> MN, +-0.9, Table 4.2) are not symmetric about the standing angles, so at rest they command
  an offset (knees -0.5 rad, ankle rolls +-0.3, shoulders -0.5 with the code's gains); theta_0 = standing - that
  offset.
- **G**: the amplitude of the first harmonic of each joint's command is a target amplitude (``TARGETS``), with the
  network driven "kinematically" (each joint's angle input = its last command: an ideal servo), measured over the
  last 4 s of 10 s. The targets are the first harmonics of the open-loop gait of ``tests/bodies/test_humanoid.py`` (CPG-
  HUMANOID.md §8's recipe: hip pitch 0.15 sin phi, knee lift 0.6 max(0, cos phi), hip pitch - lift/2, ankle pitch
  -(hip pitch + knee), roll 0.1): knee 0.6/2 = 0.3, hip and ankle pitch sqrt(0.15^2 + (0.6/4)^2) = 0.212, rolls 0.1;
  shoulders 0.1 (chosen: the recipe keeps the arms still; the probe walked the same with 0, 0.2 or 0.4). With the PF
  fed tanh(V / A_f) (``pf_input: bounded``) the knee's target is 0.27 (``KNEE_TARGET_BOUNDED``: its reason there).

``--calibrate`` iterates both conditions (G scaled by target / measured amplitude, theta_0 re-solved, 6 rounds) and
prints the values the circuit should hold; without it the script prints what the circuit as shipped gives. ``--walk N``
then runs N trials (seeds 0..N-1, the body's ``start_noise`` ``--noise`` rad) of the gait on the flat, controller and
body in one process, and prints each trial's outcome; ``--alpha-mlr`` repeats them with other slopes alpha_MLR of (4.9)
(the sweep of scenarios/humanoid_walk.yaml). ``--set`` overrides a circuit value by key path, as the
controller's ``circuit_overrides``. About 10 s for the calibration on 2 shared cores, 0.5 s per walking trial.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.humanoid import SENSORS, Humanoid  # noqa: E402
from sfl_brain.bodies.humanoid_table import STANDING  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402
from sfl_brain.modules.cpg import CPGNetwork  # noqa: E402
from sfl_brain.modules.cpg.circuit import apply_overrides, read_circuit_data  # noqa: E402

#: first-harmonic amplitude (rad) of each joint kind's command (see the docstring)
TARGETS = {
    "shoulder_pitch": 0.1,
    "hip_pitch": 0.212,
    "hip_roll": 0.1,
    "knee": 0.3,
    "ankle_pitch": 0.212,
    "ankle_roll": 0.1,
}
#: the knee's target when the PF reads tanh(V / A_f) (circuit ``pf_input: bounded``, issue 23): 0.9 x 0.3. That input
#: squares the wave (the knee command's 3rd harmonic 23 % of the 1st, against 14 % on V), and with 0.3 rad the gait
#: walks 10/10 seeds but in 15.3-16.3 s instead of 13.1-13.3. Probe (PF alpha 1.6, ankle pitch 8, 10 seeds, noise 0.02,
#: recalibrated each): knee x1.0 15.3-16.3 s; x0.9 13.2-14.1 s, and with alpha_MLR 0.9 / 1.1 / 1.2 10/10 each
#: (14.6-15.4, 12.1-13.0, 11.3-12.2 s); x0.85 12.5-13.0 s but alpha_MLR 1.1 loses seed 8 (falls at 3.6 s); x0.8
#: 12.3-12.5 s but alpha_MLR 1.2 walks 6/10. On V the target stays 0.3 (the calibration as it was; x0.9 walks 10/10
#: there too, in 12.7-13.4 s, x0.85 9/10).
KNEE_TARGET_BOUNDED = 0.27


def targets(pf_input: str) -> dict[str, float]:
    """``TARGETS`` for a circuit whose PF reads ``pf_input`` (``potential`` or ``bounded``)."""
    return {**TARGETS, "knee": KNEE_TARGET_BOUNDED} if pf_input == "bounded" else dict(TARGETS)


DT = 0.01  # s, the control tick
SECONDS, WINDOW = 10.0, 4.0  # s: kinematic run, and its last part measured


def first_frame(inputs: list[str]) -> np.ndarray:
    """The body's sensor values at t = 0 (standing pose, feet unloaded), in the circuit's input order."""
    body = Humanoid()
    body.logging = False
    body.start_trial(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False))
    values = body.sense()
    body.close()
    names = [s.name for s in SENSORS]
    return np.array([values[names.index(name)] for name in inputs])


def kinematic(circuit, frame: np.ndarray) -> np.ndarray:
    """Commands (ticks, joints) of the network driven kinematically from ``frame``: each joint's angle input is its
    last command; the other inputs stay as in ``frame``."""
    network = CPGNetwork(circuit)
    sensors = frame.copy()
    angle_of = [(circuit.inputs.index(j.angle_input), k) for k, j in enumerate(circuit.joints)]
    out = []
    for _ in range(int(round(SECONDS / DT))):
        command = network.command()
        for i, k in angle_of:
            sensors[i] = command[k]
        network.advance(sensors)
        out.append(network.command())
    return np.array(out)


def first_harmonic(commands: np.ndarray, reference: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Amplitude (rad) and phase (deg, relative to joint ``reference``) of each column's strongest Fourier
    component over the last ``WINDOW`` s, and its period (s)."""
    window = commands[-int(round(WINDOW / DT)) :]
    spectrum = np.fft.rfft(window - window.mean(axis=0), axis=0)
    k = int(np.argmax(np.abs(spectrum[1:, reference]))) + 1
    amplitude = np.abs(spectrum[k]) * 2 / len(window)
    phase = np.degrees(np.angle(spectrum[k] / spectrum[k, reference]))
    return amplitude, phase, len(window) * DT / k


def rest_command(circuit, frame: np.ndarray) -> np.ndarray:
    """The command at rest (no kick, V = q = 0) on ``frame``: what theta_0 + G (MN_E - MN_F) is at t = 0."""
    data = circuit.model_dump()
    data["kicks"] = []
    network = CPGNetwork(apply_overrides(data, {}))
    network.advance(frame)
    return network.command()


def calibrate(data: dict, frame: np.ndarray, rounds: int = 6) -> dict:
    """Gains and theta_0 meeting both conditions of the docstring, starting from the circuit's own."""
    data = yaml.safe_load(yaml.safe_dump(data))  # a copy
    target = targets(data.get("pf_input", "potential"))
    for _ in range(rounds):
        circuit = apply_overrides(data, {})
        amplitude, _, _ = first_harmonic(kinematic(circuit, frame), circuit.joint_index("hip_pitch_l"))
        for k, joint in enumerate(data["joints"]):
            joint["gain"] = float(joint["gain"] * target[joint["name"][:-2]] / amplitude[k])
        # the rest command is theta_0 + G (MN_E - MN_F) with MN set by the frame alone: solve for theta_0
        circuit = apply_overrides(data, {})
        offset = rest_command(circuit, frame) - np.array([j.theta0 for j in circuit.joints])
        for k, joint in enumerate(data["joints"]):
            joint["theta0"] = float(STANDING[joint["name"]] - offset[k])
    return data


def report(data: dict, frame: np.ndarray, shipped: dict) -> None:
    circuit = apply_overrides(data, {})
    commands = kinematic(circuit, frame)
    amplitude, phase, period = first_harmonic(commands, circuit.joint_index("hip_pitch_l"))
    at_rest = rest_command(circuit, frame)
    print(f"period {period:.3f} s; phases relative to hip_pitch_l's command; rest = command at t = 0 - standing")
    print("| joint | gain | theta0 | shipped gain | shipped theta0 | amplitude rad | phase deg | rest rad |")
    print("|---|---|---|---|---|---|---|---|")
    for k, joint in enumerate(circuit.joints):
        old = next(j for j in shipped["joints"] if j["name"] == joint.name)
        print(
            f"| {joint.name} | {joint.gain:.4f} | {joint.theta0:.4f} | {old['gain']:.4f} | {old['theta0']:.4f} | "
            f"{amplitude[k]:.3f} | {phase[k]:+.0f} | {at_rest[k] - STANDING[joint.name]:+.4f} |"
        )


def walk(overrides: dict, trials: int, noise: float, alpha_mlr: list[float]) -> None:
    """``trials`` seeds of the gait on the flat, for each descending-control slope alpha_MLR of (4.9)."""
    body = Humanoid(Humanoid.Params(start_noise=noise))
    body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao", circuit_overrides=overrides)))
    print("| alpha_MLR | seed | success | time s | distance m | lateral m | eta |")
    print("|---|---|---|---|---|---|---|")
    for alpha in alpha_mlr:
        for seed in range(trials):
            controller_params = {} if alpha == 1.0 else {"alpha_mlr": alpha}
            request = TrialRequest(
                trial_id=seed, seed=seed, body_params={}, controller_params=controller_params, log=False
            )
            result = body.handle(request)
            m = result.metrics
            print(
                f"| {alpha:g} | {seed} | {result.success} | {m['time']:.2f} | {m['distance']:.2f} | "
                f"{m['lateral']:+.2f} | {result.quality:.5f} |"
            )
    body.close()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--calibrate", action="store_true")
    parser.add_argument("--walk", type=int, default=0, help="trials of the gait on the flat")
    parser.add_argument("--noise", type=float, default=0.02, help="the body's start_noise, rad")
    parser.add_argument("--alpha-mlr", type=float, nargs="+", default=[1.0], help="(4.9) slopes to walk with")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    overrides = {}
    for item in args.set:
        key, value = item.split("=", 1)
        overrides[key] = yaml.safe_load(value)
    shipped = read_circuit_data("humanoid_nao")
    data = apply_overrides(shipped, overrides).model_dump()
    frame = first_frame(data["inputs"])
    if args.calibrate:
        data = calibrate(data, frame)
        calibrated = {
            f"joints.{k}.{key}": round(j[key], 4) for k, j in enumerate(data["joints"]) for key in ("gain", "theta0")
        }
        overrides = {**overrides, **calibrated}
    report(data, frame, shipped)
    if args.walk:
        walk(overrides, args.walk, args.noise, args.alpha_mlr)


if __name__ == "__main__":
    main()
