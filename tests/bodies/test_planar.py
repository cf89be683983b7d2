"""The planar biped and the reflexive controller (thesis chapter 3)."""

import json

import numpy as np
import pyarrow.parquet as pq

from sfl_brain.bodies.planar_biped import PlanarBiped
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.reflex import ReflexController, sensor_neuron
from sfl_brain.protocols.local import run_local
from sfl_brain.recording.records import read_records
from sfl_brain.runtime.placement import usable_cpus
from sfl_brain.scenario import load

from ..conftest import SCENARIOS, sfl_run
from ..runtime.test_e2e import rrd_rows, stable


def trial(alpha, theta, slope=0.0, duration=10.0, seed=0):
    body = PlanarBiped(PlanarBiped.Params(duration=duration))
    body.link = InProcessLink(ReflexController())
    return body, body.handle(
        TrialRequest(
            trial_id=0,
            seed=seed,
            body_params={"slope_deg": slope},
            controller_params={"alpha_hip": alpha, "theta_hip_max_deg": theta},
            log=False,
        )
    )


def test_golden_structure():
    body, _ = trial(10, 110, duration=0.05)
    assert len(body.space.bodies) == 5  # trunk, two thighs, two shanks
    kinds = sorted(type(c).__name__ for c in body.space.constraints)
    assert kinds.count("PivotJoint") == 4 and kinds.count("RotaryLimitJoint") == 4
    assert kinds.count("DampedRotarySpring") == 5  # 4 motor back-EMF dampers + the boom
    assert body.space.collision_slop == 0.001
    mass = sum(b.mass for b in body.space.bodies)
    assert abs(mass - (0.45 + 2 * (0.20 + 0.08))) < 1e-9


def test_sensor_neuron_3_4():
    assert sensor_neuron(10.0, 1.0, 1.0) == 0.5
    assert sensor_neuron(10.0, 1.0, 2.0) > 0.99 and sensor_neuron(10.0, 1.0, 0.0) < 0.01


class NeuronByNeuron:
    """Fig. 3.7 written out one synapse at a time, the reference for the vectorised controller."""

    def __init__(self, p, alpha_hip, theta_hip_max_deg):
        self.p, self.alpha, self.theta = p, alpha_hip, np.radians(theta_hip_max_deg)
        self.y = {(k, s): 0.0 for k in ("hip_EM", "hip_FM", "knee_EM", "knee_FM") for s in (0, 1)}
        self.stance, self.previous = None, (0.0, 0.0)

    def step(self, s):
        p, rad = self.p, np.radians
        hip, knee, ground = s[0:2], s[2:4], s[4:6]
        down = [ground[i] > 0.5 and self.previous[i] < 0.5 for i in (0, 1)]
        if any(down):
            self.stance = down.index(True) if sum(down) == 1 else int(hip[1] > hip[0])
        elif self.stance is None and any(ground):
            self.stance = int(ground[1] > ground[0])
        self.previous = tuple(ground)
        volts = {}
        for i in (0, 1):
            own = 1.0 if self.stance == i else 0.0
            other = 1.0 if self.stance == 1 - i else 0.0
            hip_e = sensor_neuron(self.alpha, self.theta, hip[i])  # (3.4)
            hip_f = sensor_neuron(p.alpha_hip_flexor, -rad(p.theta_hip_min_deg), -hip[i])
            stretch = sensor_neuron(p.alpha_as, self.theta - rad(p.as_lead_deg), hip[i])
            knee_e = sensor_neuron(p.alpha_knee, rad(p.theta_knee_extended_deg), knee[i])
            knee_f = sensor_neuron(p.alpha_knee, -rad(p.theta_knee_flexed_deg), -knee[i])
            we, wi = p.w_excite, p.w_inhibit
            drive = {
                "hip_EM": we * other + wi * hip_e,  # (b) swing, (c) articular reflex
                "hip_FM": we * own + wi * hip_f,  # (a) stance, (c)
                "knee_EM": we * own + we * stretch + wi * knee_e,  # (a), (d) extension reflex, (c)
                "knee_FM": we * other + wi * stretch + wi * knee_f,  # (b), (d), (c)
            }
            u = {}
            for k, d in drive.items():  # (3.5), integrated exactly over one tick
                self.y[k, i] += (1 - np.exp(-p.control_dt / p.tau)) * (d - self.y[k, i])
                u[k] = 1 / (1 + np.exp(p.alpha_motor * (p.theta_motor - self.y[k, i])))
            volts["hip", i] = p.m_hip * (u["hip_EM"] - u["hip_FM"])  # (3.6)
            volts["knee", i] = p.m_knee * (u["knee_EM"] - u["knee_FM"])
        return np.array([volts["hip", 0], volts["hip", 1], volts["knee", 0], volts["knee", 1]])


def test_vectorised_controller_matches_the_network_neuron_by_neuron():
    from sfl_brain.messages import ControllerReset, SensorFrame

    rng = np.random.default_rng(3)
    sensors = ["hip_l", "hip_r", "knee_l", "knee_r", "contact_l", "contact_r", "slope", "pitch"]
    for alpha, theta in ((10.0, 110.0), (3.0, 140.0), (18.0, 95.0)):
        fast = ReflexController()
        fast.handle(
            ControllerReset(
                trial_id=0,
                seed=0,
                params={"alpha_hip": alpha, "theta_hip_max_deg": theta},
                sensors=sensors,
                commands=list(fast.WRITES),
            )
        )
        reference = NeuronByNeuron(fast.params, alpha, theta)
        for tick in range(400):
            s = np.concatenate([rng.uniform(0.8, 2.4, 2), rng.uniform(-1.2, 0, 2), rng.random(2) < 0.5, [0, 0]])
            got = fast.handle(SensorFrame(trial_id=0, tick=tick, values=s.astype(float))).values
            np.testing.assert_allclose(got, reference.step(s), rtol=0, atol=1e-12)


def test_a_good_gait_walks_and_is_deterministic():
    _, first = trial(10, 110)
    _, second = trial(10, 110)
    assert first == second
    assert first.success and not first.metrics["fell"]
    assert first.metrics["distance"] > 2.0 and first.metrics["steps"] >= 10
    assert first.quality > 0 and first.metrics["energy"] > 0


def test_no_hip_swing_falls_and_is_detected_as_a_fall():
    _, result = trial(0.0, 120)  # alpha 0: the extensor sensor half-inhibits the swing for ever
    assert not result.success and result.metrics["fell"]
    assert result.metrics["time"] < 10.0  # the trial stopped at the fall


def test_too_long_a_stride_stalls_and_is_not_a_success():
    _, result = trial(10, 145)
    assert not result.success and not result.metrics["fell"] and result.metrics["distance"] < 0.5


def test_the_steeper_uphill_the_fewer_strides_walk():
    """Slope changes the outcome, one way: on a 3 x 4 grid of (alpha_hip, theta_hip_max), each
    steeper uphill slope leaves fewer settings that walk (7, 6, 5, 4 of 12 at 0, 3, 6, 9 deg), for
    every trial seed tried."""
    grid = [(a, t) for a in (5, 10, 15) for t in (100, 110, 120, 130)]
    for seed in (0, 1):
        walks = [sum(trial(a, t, slope=s, seed=seed)[1].success for a, t in grid) for s in (0.0, 3.0, 6.0, 9.0)]
        assert walks[0] > walks[1] > walks[2] > walks[3] > 0, (seed, walks)


def test_learning_run_end_to_end_with_processes(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "quickstart.yaml", out, "protocol.trials=12", "record.body_every=4")
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["trials"] == 12 and summary["status"] == "completed"
    # the body's metric columns carry the units it declares (docs/records.md; issue 32 found them empty)
    units = {f.name: f.metadata[b"unit"].decode() for f in pq.read_schema(out / "trials.parquet")}
    assert {"m_distance": "m", "m_velocity": "m/s", "m_time": "s", "m_energy": "J"}.items() <= units.items()
    # lockstep over Zenoh gives the same trials as the same scenario in one process
    local = run_local(load(SCENARIOS / "quickstart.yaml", ["protocol.trials=12"]))
    assert stable(local) == stable(read_records(out))
    counts = rrd_rows(out / "recording.rrd")
    assert counts["/body/walker"] > 0 and counts["/body/joints/hip_l"] > 0 and counts["/body/motors/v_hip_l"] > 0
    # the controller process logged its neurons on the same logged trials, on the same timelines
    assert counts["/controller/neurons/motor/hip_EM_l"] == counts["/body/joints/hip_l"]
    assert counts["/controller/neurons/sensor/stretch_AS_r"] == counts["/body/joints/hip_l"]
    assert counts["/trials/success"] == 12 and counts["/acc/success_map/neurons"] >= 12
    assert (out / "acc.npz").exists()
    assert np.load(out / "acc.npz")["success_weights"].shape == (100, 2)
    # the body and its controller shared a core (lockstep.pin_cpus: auto), as the OS says
    logs = {name: (out / "logs" / f"{name}.log").read_text() for name in ("body", "controller", "acc")}
    cpus = usable_cpus()
    if len(cpus) >= 2:
        assert f"pinned to cores [{cpus[-1]}]" in logs["body"]
        assert f"pinned to cores [{cpus[-1]}]" in logs["controller"]
    assert all("pinned" not in logs[name] for name in logs if len(cpus) < 2)


def test_exploit_walks_with_the_parameters_of_the_given_maps(tmp_path):
    """The exploit protocol restores the ACC from protocol.maps and switches its success neurons."""
    from sfl_brain.modules.acc import ACC

    def maps_with(alpha_unit, theta_unit, path):
        acc = ACC(ACC.Params(shape=(5, 5, 5), dim=3), seed=0)
        acc.success_map.weights[:, 0] = alpha_unit
        acc.success_map.weights[:, 1] = theta_unit
        acc.checkpoint(path)
        return path

    walking = maps_with(0.9, 0.22, tmp_path / "walking.npz")  # alpha 18/rad, theta 103 deg: inside Fig. 3.8's region
    stalling = maps_with(0.05, 0.9, tmp_path / "stalling.npz")  # alpha 1/rad, theta 144 deg: outside it
    overrides = ["protocol.trials=1", "modules.body.params.duration=6", "modules.body.params.min_distance=2"]
    plan = load(SCENARIOS / "e3_5_terrain.yaml", [*overrides, f"protocol.maps={walking}"])
    assert next(i for i in plan.instances if i.name == "acc").params["restore"] == str(walking.resolve())
    walked = run_local(plan)[-1]
    stalled = run_local(load(SCENARIOS / "e3_5_terrain.yaml", [*overrides, f"protocol.maps={stalling}"]))[-1]
    assert walked["success"] and walked["m_distance"] > 2.0
    assert not stalled["success"] and stalled["m_distance"] < 1.0


def test_garbage_on_the_tick_keys_is_dropped_and_changes_nothing(tmp_path):
    """Malformed payloads published onto a running run's lockstep keys (both layouts), on the mesh and on the
    pair's lockstep link, are logged and dropped by the controller's host and never reach the body; the trials
    come out as without them."""
    import threading

    import msgspec

    from sfl_brain.messages import SCHEMA_VERSION, SensorFrame, encode
    from sfl_brain.runtime import bus

    from ..conftest import TickStranger, joined_run

    out = tmp_path / "run"
    sets = ["protocol.trials=10", "record.body_every=0"]
    garbage = [
        b"\x00garbage\xff",  # not msgpack
        msgspec.msgpack.encode([SCHEMA_VERSION, "no.such.tag", []]),
        b"\xc1",  # packed, too short
        b"\xc1\x09\x12controller.sensors" + bytes(24),  # packed, another schema version
        b"\xc1\x02\x05bogus" + bytes(24),  # packed, unknown tag
        encode(SensorFrame(trial_id=0, tick=0, values=np.zeros(3)))[:-3],  # packed, cut short
    ]
    stop = threading.Event()
    with joined_run(SCENARIOS / "quickstart.yaml", out, *sets, modules=5) as (proc, session, run_id):
        keys = [bus.key(run_id, "controller", "controller.sensors"), bus.key(run_id, "body", "body.command")]
        # the ticks go over the pair's own link, off the mesh (this user may connect to it): spray both
        link = TickStranger(out)

        def spray():
            while not stop.wait(0.02):  # slow enough never to fill a 64-deep ring between two reads
                for key in keys:
                    for payload in garbage:
                        session.put(key, payload)
                        link.put(key, payload)

        sprayer = threading.Thread(target=spray)
        sprayer.start()
        try:
            assert proc.wait(timeout=240) == 0, proc.stderr.read()
        finally:
            stop.set()
            sprayer.join()
            link.close()
    # none of it carries the trial's stream nonce: the controller drops it as foreign, counts it, logs it once
    counted = json.loads((out / "logs" / "controller.counters.json").read_text())["dropped"]
    assert link.sent > 0 and counted.get("foreign", 0) > 0, counted
    assert "not the current trial's stream nonce" in (out / "logs" / "controller.log").read_text()
    # the body's end of the link connects to its controller only: none of it reached the body (its own checks:
    # tests/runtime/test_placement_run.py)
    assert json.loads((out / "logs" / "body.counters.json").read_text())["dropped"] == {}
    local = run_local(load(SCENARIOS / "quickstart.yaml", sets))
    assert stable(local) == stable(read_records(out))


def test_a_controller_step_may_return_a_list_and_still_sends_a_float64_vector():
    from sfl_brain.body import Controller
    from sfl_brain.messages import ControllerReset, SensorFrame, decode, encode

    class Listing(Controller):
        WRITES = ("v_hip_l", "v_hip_r")

        def configure(self, params, seed):
            pass

        def step(self, sensors):
            return [1, 2.5]

    controller = Listing()
    controller.handle(ControllerReset(trial_id=0, seed=0, params={}, sensors=["x"], commands=list(Listing.WRITES)))
    command = decode(encode(controller.handle(SensorFrame(trial_id=0, tick=3, values=np.zeros(1)))))
    assert command.tick == 3 and command.values.dtype == np.float64
    np.testing.assert_array_equal(command.values, [1.0, 2.5])


HUNG_ONCE = '''
from pathlib import Path

from sfl_brain.modules.controllers.reflex import ReflexController


class HungOnce(ReflexController):
    """The reflex controller, but it spins on one tick, once in the run (a marker file beside this one)."""

    def configure(self, params, seed):
        self._ticks = 0
        super().configure(params, seed)

    def step(self, sensors):
        marker = Path(__file__).with_suffix(".hung")
        if self._ticks == 50 and not marker.exists():
            marker.write_text("hung")
            while True:
                pass
        self._ticks += 1
        return super().step(sensors)
'''


def test_a_controller_that_spins_in_a_tick_is_found_hung_by_its_body_restarted_and_the_trial_retried(tmp_path):
    """The body's watchdog finds its controller hung (it could run for timeouts.tick and did not answer), the
    supervisor kills it and restarts it (the default for controllers), and the trial is retried and recorded as
    retried; the records are otherwise those of a controller that never hangs."""
    (tmp_path / "hung_once.py").write_text(HUNG_ONCE)
    sets = ["protocol.trials=4", "record.body_every=0"]
    hung = [*sets, f"modules.controller.impl={tmp_path / 'hung_once.py'}:HungOnce", "timeouts.tick=1"]
    out = tmp_path / "run"
    done = sfl_run(SCENARIOS / "quickstart.yaml", out, *hung)
    assert done.returncode == 0, done.stderr
    assert "trial 0 interrupted" in done.stdout and "did not answer tick 50 (timeouts.tick 1 s): hung" in done.stdout
    assert "module `controller` was hung" in done.stderr and "killed; restarting (1/3)" in done.stderr, done.stderr
    rows = read_records(out)
    assert [(r["trial"], r["attempt"]) for r in rows if r["kind"] == "retry"] == [(0, 1)]
    clean = run_local(load(SCENARIOS / "quickstart.yaml", sets))
    assert stable(clean) == stable([r for r in rows if r["kind"] != "retry"])
