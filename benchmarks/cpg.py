"""Cost of the MLMP-CPG per 10-ms control tick (10 RK4 sub-steps of 1 ms), beside the physics it drives.

    python benchmarks/cpg.py [--ticks 3000]      (tiny: --ticks 200)

Per tick, interleaved so that all see the same machine load: ``CPGNetwork.advance`` of the planar circuit
(7 joints, 14 RG cells) and of the humanoid circuit (12 joints, 24 cells), each fed a fixed sensor frame, and
one physics tick of a walker stepped with a fixed open-loop command. The 8-link planar walker of issue 15 is
not built yet: the physics figure is the STAND-IN chapter-3 planar biped (``bodies/planar_biped.py``,
5 bodies, 4 driven joints), stepped as ``benchmarks/planar.py`` (a) steps it.
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
from sfl_brain.modules.cpg import CPGNetwork, load_circuit  # noqa: E402


def cpg(name: str) -> tuple[CPGNetwork, np.ndarray]:
    circuit = load_circuit(name)
    network = CPGNetwork(circuit)
    sensors = np.zeros(len(circuit.inputs))
    for joint in circuit.joints:  # a plausible frame: every joint at its command offset
        if joint.angle_input:
            sensors[circuit.inputs.index(joint.angle_input)] = joint.theta0
    return network, sensors


def physics() -> PlanarBiped:
    body = PlanarBiped()
    body.logging = False
    body.start_trial(REQUEST)
    return body


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--ticks", type=int, default=3000, help="control ticks timed per item (10 ms of sim each)")
    args = parser.parse_args()
    planar, planar_sensors = cpg("planar_8link")
    humanoid, humanoid_sensors = cpg("humanoid_nao")
    command = np.array([1.0, -1.0, 0.5, 0.5])
    body = physics()
    samples = {"planar": [], "humanoid": [], "physics": []}
    for tick in range(args.ticks):
        if tick % 1000 == 999:  # a 10-s trial of the stand-in ends; start another (not timed)
            body = physics()
        t0 = time.perf_counter()
        planar.advance(planar_sensors)
        t1 = time.perf_counter()
        humanoid.advance(humanoid_sensors)
        t2 = time.perf_counter()
        body.actuate(command)
        t3 = time.perf_counter()
        samples["planar"].append(t1 - t0)
        samples["humanoid"].append(t2 - t1)
        samples["physics"].append(t3 - t2)
    medians = {k: float(np.median(v)) for k, v in samples.items()}
    print(f"one 10-ms control tick (10 RK4 sub-steps of 1 ms for the CPG), {args.ticks} ticks, interleaved:")
    print(f"  CPG planar_8link (7 joints, 14 cells)    {stats(samples['planar'])}")
    print(f"  CPG humanoid_nao (12 joints, 24 cells)   {stats(samples['humanoid'])}")
    print(f"  physics, STAND-IN ch.3 planar biped      {stats(samples['physics'])}  (the 8-link walker is not built)")
    print(
        f"  CPG / physics: planar {medians['planar'] / medians['physics']:.2f}, "
        f"humanoid {medians['humanoid'] / medians['physics']:.2f} (goal < 1)"
    )


if __name__ == "__main__":
    main()
