"""Cost of the MLMP-CPG per 10-ms control tick (10 RK4 sub-steps of 1 ms), beside the physics it drives.

    python benchmarks/cpg.py [--ticks 3000]      (tiny: --ticks 200)

Per tick, interleaved so that all see the same machine load, for the planar circuit (7 joints, 14 RG cells) and the
humanoid circuit (12 joints, 24 cells):

- ``CPGNetwork.advance`` + ``command()``: the network alone, fed a fixed sensor frame;
- the controller's tick as the framework runs it in the body's process: ``InProcessLink.step(frame)`` ->
  ``CPGController.on_sensor_frame`` (dispatch, wiring by name, the network, the ``MotorCommand``);

- a batch of ``BATCH`` (8) copies of the humanoid network (``CPGNetwork(batch=8)``: ``advance`` + ``command_all``),
  the CPG of issue 31's batched trials: its cost per copy beside one network alone;

each on both kernels of the network when numba is installed (``CPGParams.kernel``: "numpy", the default, and "numba",
the same RK4 and layers compiled, issue 31; goal: numba <= 0.4x numpy per tick), and one physics tick of

- the chapter-3 planar biped (``bodies/planar_biped.py``, 5 bodies, 4 driven joints), stepped with a fixed
  open-loop command as ``benchmarks/planar.py`` (a) steps it: the stand-in the CPG was first compared with;
- the 8-link planar walker of Fig. 4.7 (``bodies/planar_8link.py``, 8 links, 7 motors), driven by the planar CPG
  controller in closed loop (its sense and the controller are not timed, only ``actuate``); a trial that ends (a
  fall) is restarted, untimed. Left out, and said so, when that body cannot be imported.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import stats  # noqa: E402
from planar import REQUEST  # noqa: E402  (the planar benchmark's trial: the same stand-in physics)

from sfl_brain.bodies.planar_biped import PlanarBiped  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import ControllerReset, SensorFrame, TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402
from sfl_brain.modules.cpg import CPGNetwork, load_circuit  # noqa: E402
from sfl_brain.signals import names  # noqa: E402

try:  # the 8-link walker of issue 15, if this checkout has it
    from sfl_brain.bodies.planar_8link import PlanarWalker8  # noqa: E402
except ImportError:
    PlanarWalker8 = None

CIRCUITS = (("planar_8link", "7 joints, 14 cells"), ("humanoid_nao", "12 joints, 24 cells"))
BATCH = 8  # copies in the batched humanoid network (issue 31 item 4: K = 8)


def frame_for(circuit) -> np.ndarray:
    """A plausible sensor frame in the circuit's input order: every joint at its command offset."""
    sensors = np.zeros(len(circuit.inputs))
    for joint in circuit.joints:
        if joint.angle_input:
            sensors[circuit.inputs.index(joint.angle_input)] = joint.theta0
    return sensors


try:  # the compiled kernel, if numba is installed (the fast extra)
    import numba  # noqa: F401

    KERNELS = ("numpy", "numba")
except ImportError:
    KERNELS = ("numpy",)


def controller_link(name: str, kernel: str = "numpy") -> tuple[InProcessLink, np.ndarray]:
    """The CPG controller behind an in-process link, reset for a body laid out as the circuit's inputs and commands."""
    params = CPGParams(circuit=name, kernel=kernel)
    reads, writes = CPGController.signals(params)
    link = InProcessLink(CPGController(params))
    link.reset(ControllerReset(trial_id=0, seed=0, params={}, sensors=list(reads), commands=list(writes)))
    return link, frame_for(load_circuit(name))


class Walker:
    """The 8-link walker driven by the planar CPG controller; ``tick()`` times one ``actuate``."""

    def __init__(self) -> None:
        self.body = PlanarWalker8()
        self.body.logging = False
        self.link = InProcessLink(CPGController(CPGParams(circuit="planar_8link")))
        self.trial = -1
        self.start()

    def start(self) -> None:
        self.trial += 1
        request = TrialRequest(trial_id=self.trial, seed=0, body_params={}, controller_params={}, log=False)
        self.body.start_trial(request)
        sensors, commands = (list(names(s)) for s in (self.body.SENSORS, self.body.COMMANDS))
        self.link.reset(ControllerReset(trial_id=self.trial, seed=0, params={}, sensors=sensors, commands=commands))
        self.n = 0

    def tick(self) -> float:
        if self.body.done:
            self.start()
        frame = SensorFrame(trial_id=self.trial, tick=self.n, values=self.body.sense())
        command = self.link.step(frame).values
        self.n += 1
        t = time.perf_counter()
        self.body.actuate(command)
        return time.perf_counter() - t


def stand_in() -> PlanarBiped:
    body = PlanarBiped()
    body.logging = False
    body.start_trial(REQUEST)
    return body


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--ticks", type=int, default=3000, help="control ticks timed per item (10 ms of sim each)")
    args = parser.parse_args()
    networks, links = {}, {}
    for name, _ in CIRCUITS:
        circuit = load_circuit(name)
        for kernel in KERNELS:
            networks[name, kernel] = (CPGNetwork(circuit, kernel=kernel), frame_for(circuit))
            links[name, kernel] = controller_link(name, kernel)
            networks[name, kernel][0].advance(networks[name, kernel][1])  # numba compiles (or loads) on the first call
    batched = {}
    for kernel in KERNELS:
        humanoid = networks["humanoid_nao", kernel][1]
        network = CPGNetwork(load_circuit("humanoid_nao"), batch=BATCH, kernel=kernel)
        batched[kernel] = (network, np.tile(humanoid, (BATCH, 1)))
        batched[kernel][0].advance(batched[kernel][1])
    command = np.array([1.0, -1.0, 0.5, 0.5])
    biped = stand_in()
    walker = Walker() if PlanarWalker8 is not None else None
    samples: dict[str, list[float]] = {key: [] for key in ("biped", "walker")}
    clock = time.perf_counter
    for tick in range(args.ticks):
        if tick % 1000 == 999:  # a 10-s trial of the stand-in ends; start another (not timed)
            biped = stand_in()
        for (name, kernel), (network, sensors) in networks.items():
            t0 = clock()
            network.advance(sensors)
            network.command()
            t1 = clock()
            link, sensors = links[name, kernel]
            frame = SensorFrame(trial_id=0, tick=tick, values=sensors)
            t2 = clock()
            link.step(frame)
            t3 = clock()
            tag = "" if kernel == "numpy" else f" {kernel}"
            samples.setdefault(f"{name} advance{tag}", []).append(t1 - t0)
            samples.setdefault(f"{name} controller{tag}", []).append(t3 - t2)
        for kernel, (network, sensors) in batched.items():
            t0 = clock()
            network.advance(sensors)
            network.command_all()
            samples.setdefault(f"batch {kernel}", []).append(clock() - t0)
        t0 = clock()
        biped.actuate(command)
        samples["biped"].append(clock() - t0)
        if walker is not None:
            samples["walker"].append(walker.tick())

    medians = {key: float(np.median(v)) for key, v in samples.items()}
    physics = [("biped", "ch.3 biped (stand-in)")] + ([("walker", "8-link walker")] if walker else [])
    rows = []
    for name, size in CIRCUITS:
        for kernel in KERNELS:
            tag = "" if kernel == "numpy" else f" {kernel}"
            rows.append((f"CPG {name} ({size}), {kernel}: CPGNetwork.advance + command", f"{name} advance{tag}"))
            rows.append(
                (f"CPG {name} ({size}), {kernel}: controller tick (on_sensor_frame)", f"{name} controller{tag}")
            )
    rows.append(("physics, ch.3 planar biped (the stand-in, 4 joints)", "biped"))
    if walker is not None:
        rows.append((f"physics, 8-link planar walker (7 joints, CPG-driven, {walker.trial + 1} trials)", "walker"))
    width = max(len(label) for label, _ in rows) + 2
    print(f"one 10-ms control tick (CPG: 10 RK4 sub-steps of 1 ms), {args.ticks} ticks, interleaved:")
    for label, key in rows:
        print(f"  {label:<{width}}{stats(samples[key])}")
    if walker is None:
        print("  (no 8-link planar walker in this checkout, bodies/planar_8link.py: the stand-in's physics only)")
    print(f"CPG / physics, medians (goal < 1):{''.join(f'{label:>24}' for _, label in physics)}")
    for name, _ in CIRCUITS:
        for kind in ("advance", "controller"):
            for kernel in KERNELS:
                tag = "" if kernel == "numpy" else f" {kernel}"
                ratios = "".join(f"{medians[f'{name} {kind}{tag}'] / medians[key]:>24.2f}" for key, _ in physics)
                print(f"  {f'{name} {kind}{tag}':<32}{ratios}")
    print(f"humanoid_nao, a batch of {BATCH} copies (advance + command_all), per tick and per copy:")
    for kernel in KERNELS:
        tag = "" if kernel == "numpy" else f" {kernel}"
        whole, alone = medians[f"batch {kernel}"], medians[f"humanoid_nao advance{tag}"]
        print(f"  {kernel:<8}{whole * 1e6:8.1f} us a tick, {whole / BATCH * 1e6:6.1f} us a copy: "
              f"{whole / BATCH / alone:.2f} of one network alone ({alone * 1e6:.1f} us)")  # fmt: skip
    if "numba" in KERNELS:  # medians of the per-tick ratios: each pair timed in the same tick
        print("numba / numpy per tick, median of the ratios (goal <= 0.4):")
        for name, _ in CIRCUITS:
            for kind in ("advance", "controller"):
                ratio = np.median(np.array(samples[f"{name} {kind} numba"]) / np.array(samples[f"{name} {kind}"]))
                print(f"  {f'{name} {kind}':<32}{ratio:>8.2f}")
    else:
        print("(numba is not installed: the numpy kernel only; pip install -e '.[fast]' adds the compiled one)")


if __name__ == "__main__":
    main()
