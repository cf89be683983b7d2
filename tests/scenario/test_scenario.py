import json
import textwrap

import numpy as np
import pytest
import yaml

from sfl_brain.scenario import ScenarioError, load

from ..conftest import SCENARIOS, sfl

BASE = """
name: t
seed: 1
protocol: {kind: learn, trials: 5}
space:
  - {name: x, target: body.x, low: 0, high: 1}
  - {name: y, target: body.y, low: 0, high: 1}
modules:
  acc: {impl: acc}
  vigilance: {impl: vigilance, params: {mode: fixed}}
  ofc: {impl: ofc}
  body: {impl: analytic}
"""


def errors(write_scenario, text):
    path = write_scenario(textwrap.dedent(text))
    with pytest.raises(ScenarioError) as info:
        load(path)
    return str(info.value), path


def test_shipped_scenarios_are_valid(tmp_path):
    from sfl_brain.modules.acc import ACC

    maps = tmp_path / "acc.npz"  # exploit scenarios read the maps of a learn run: give them some
    ACC(ACC.Params(shape=(5, 5, 5), dim=3), seed=0).checkpoint(maps)
    run = tmp_path / "learnt"  # conditions read the best parameters of completed learn runs (best_of): give them one
    run.mkdir()
    point = {"gain_pitch": 1.0, "gain_roll": 1.0, "sigma_s": 4.0, "v_unit": [0.5, 0.5, 0.5]}
    (run / "summary.json").write_text(json.dumps({"status": "completed", "best": {"neuron_point": point}}))
    for path in sorted(SCENARIOS.glob("*.yaml")):
        text = path.read_text()
        raw = yaml.safe_load(text)
        sets = [f"protocol.maps={maps}"] if "kind: exploit" in text else []
        sets += [f"protocol.best_of.{name}={run}" for name in (raw["protocol"].get("best_of") or {})]
        load(path, sets)


def test_a_scenario_whose_learnt_runs_are_missing_says_which(tmp_path):
    """On a fresh clone, e5_switch.yaml's learn runs do not exist yet: the check names each one, not a traceback."""
    with pytest.raises(ScenarioError) as info:
        load(
            SCENARIOS / "e5_switch.yaml",
            [f"protocol.best_of.{n}={tmp_path / n}" for n in ("flat", "uphill", "downhill")],
        )
    for name in ("flat", "uphill", "downhill"):
        assert f"protocol.best_of.{name}: expected a completed learn run's folder (with summary.json)" in str(
            info.value
        )
    assert len(str(info.value).splitlines()) == 3  # each missing run said once, not again at every reference to it


def test_bad_enum_names_file_path_expected_given_and_nearest(write_scenario):
    text, path = errors(write_scenario, BASE.replace("mode: fixed", "mode: adaptve"))
    assert (
        f"{path}: modules.vigilance.params.mode: expected one of 'fixed', 'scheduled' or 'adaptive'; "
        "got 'adaptve' (did you mean `adaptive`?)" in text
    )


def test_unknown_key_suggests_nearest(write_scenario):
    text, _ = errors(write_scenario, BASE.replace("seed: 1", "sed: 1"))
    assert "sed: unknown key" in text and "(did you mean `seed`?)" in text


def test_unknown_module_param_suggests_nearest(write_scenario):
    text, _ = errors(write_scenario, BASE.replace("params: {mode: fixed}", "params: {mode: fixed, stepp: 0.1}"))
    assert "modules.vigilance.params.stepp: unknown key" in text and "`step`" in text


def test_unknown_implementation_suggests_registered_name(write_scenario):
    text, _ = errors(write_scenario, BASE.replace("impl: vigilance", "impl: vigilence"))
    assert "modules.vigilance.impl: no registered implementation 'vigilence' (did you mean `vigilance`?)" in text


def test_out_of_range_and_wrong_type(write_scenario):
    text, _ = errors(write_scenario, BASE.replace("trials: 5", "trials: 0").replace("seed: 1", "seed: abc"))
    assert "protocol.trials: input should be greater than or equal to 1; got 0" in text
    assert "seed: expected an integer; got 'abc'" in text  # was "input should be a valid integer"


def test_missing_module_is_a_wiring_error(write_scenario):
    text, _ = errors(write_scenario, BASE.replace("  ofc: {impl: ofc}\n", ""))
    assert "protocol `learn` sends `ofc.grade` (to grade successful trials) but no module handles it" in text
    assert "(did you mean `ofc: {impl: ofc}`?)" in text


def test_axis_target_must_exist_on_the_body(write_scenario):
    text, _ = errors(write_scenario, BASE.replace("target: body.y", "target: body.yy"))
    assert "space.1.target: AnalyticBody takes trial parameters ['x', 'y', 'z']; got 'yy'" in text


MISWIRED = """
from sfl_brain.body import Controller


class Miswired(Controller):
    READS = {reads}
    WRITES = {writes}
    TRIAL_PARAMS = ("alpha_hip", "theta_hip_max_deg")

    def configure(self, params, seed):
        pass

    def step(self, sensors):
        return sensors
"""
WALKER = """
name: t
seed: 1
protocol: {kind: learn, trials: 5}
space:
  - {name: a, target: controller.alpha_hip, low: 0, high: 1}
  - {name: t, target: controller.theta_hip_max_deg, low: 90, high: 140}
modules:
  acc: {impl: acc}
  vigilance: {impl: vigilance}
  ofc: {impl: ofc}
  body: {impl: planar_biped}
  controller: {impl: miswired.py:Miswired}
"""
HIPS_KNEES = ("v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r")


def test_a_sensor_the_body_lacks_is_named_with_both_ends(write_scenario):
    write_scenario(MISWIRED.format(reads=("hip_left", "knee_l"), writes=HIPS_KNEES), "miswired.py")
    text, _ = errors(write_scenario, WALKER)
    assert (
        "modules.controller: controller `Miswired` reads sensors hip_left (did you mean `hip_l`?) that "
        "body `body` (PlanarBiped) does not have; it has ['hip_l', 'hip_r', 'knee_l'" in text
    )


def test_a_command_one_end_lacks_is_named_with_both_ends(write_scenario):
    write_scenario(MISWIRED.format(reads=("hip_l",), writes=HIPS_KNEES[:3]), "miswired.py")
    text, _ = errors(write_scenario, WALKER)
    assert (
        "modules.controller: body `body` (PlanarBiped) takes commands v_knee_r that controller `Miswired` "
        "does not have; it has ['v_hip_l', 'v_hip_r', 'v_knee_l']" in text
    )
    write_scenario(MISWIRED.format(reads=("hip_l",), writes=(*HIPS_KNEES, "v_ankle_l")), "overwired.py")
    text, _ = errors(write_scenario, WALKER.replace("miswired.py", "overwired.py"))
    assert "controller `Miswired` writes commands ['v_ankle_l'] that body `body` (PlanarBiped) does not take" in text


def test_signals_are_matched_by_name_in_any_order(write_scenario):
    """The same controller wired to a body that lists its signals in another order sees the same
    sensors and drives the same joints."""
    write_scenario(MISWIRED.format(reads=("knee_l", "hip_r"), writes=HIPS_KNEES[::-1]), "reordered.py")
    load(write_scenario(WALKER.replace("miswired.py", "reordered.py")))  # a valid wiring: sfl check passes
    from sfl_brain.messages import ControllerReset, SensorFrame
    from sfl_brain.registry import resolve

    cls, _ = resolve("reordered.py:Miswired", base_dir=write_scenario("", "x.yaml").parent)

    class EchoFour(cls):
        READS = ("knee_l", "hip_r", "hip_l", "knee_r")

    for sensors in (["hip_l", "hip_r", "knee_l", "knee_r"], ["knee_r", "knee_l", "hip_r", "hip_l", "pitch"]):
        controller = EchoFour()
        controller.handle(ControllerReset(trial_id=0, seed=0, params={}, sensors=sensors, commands=list(HIPS_KNEES)))
        values = {"hip_l": 1.0, "hip_r": 2.0, "knee_l": 3.0, "knee_r": 4.0, "pitch": 9.0}
        frame = SensorFrame(trial_id=0, tick=0, values=np.array([values[s] for s in sensors]))
        # step echoes (knee_l, hip_r, hip_l, knee_r) as WRITES (v_knee_r, v_knee_l, v_hip_r, v_hip_l)
        command = controller.handle(frame)
        # so v_knee_r = knee_l, v_knee_l = hip_r, v_hip_r = hip_l, v_hip_l = knee_r, in the body's order:
        assert command.values.tolist() == [4.0, 1.0, 2.0, 3.0]


def test_cli_check_exits_2_without_traceback(write_scenario):
    path = write_scenario(textwrap.dedent(BASE.replace("kind: learn", "kind: lern")))
    done = sfl("check", str(path))
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert (
        "protocol.kind: expected one of 'learn', 'sweep', 'exploit', 'conditions'; got 'lern' (did you mean `learn`?)"
        in done.stderr
    )


def test_cli_check_reports_yaml_syntax_errors(write_scenario):
    path = write_scenario("name: [unclosed\n")
    done = sfl("check", str(path))
    assert done.returncode == 2 and "not valid YAML" in done.stderr and "Traceback" not in done.stderr


def test_set_overrides_are_validated_too():
    done = sfl("check", str(SCENARIOS / "analytic_learn.yaml"), "--set", "modules.acc.params.shape=[0, 3]")
    assert done.returncode == 2 and "modules.acc.params.shape.0" in done.stderr


def test_lockstep_processes_are_the_body_workers_and_their_controller_processes():
    """Where they run is tests/runtime/test_placement.py's."""
    quick = SCENARIOS / "quickstart.yaml"
    assert load(quick).lockstep_processes == ["body", "controller"]  # ACC, vigilance, OFC exchange no ticks
    assert load(quick).scenario.lockstep.pin_cpus == "auto"  # each pair on a core of its own
    two = load(quick, ["modules.body.workers=2"]).lockstep_processes
    assert two == ["body.0", "controller.0", "body.1", "controller.1"]
    assert load(quick, ["modules.body.workers=2", "modules.controller.colocate=true"]).lockstep_processes == [
        "body.0",
        "body.1",
    ]
    assert load(SCENARIOS / "analytic_learn.yaml").lockstep_processes == ["body"]
    assert load(quick).scenario.lockstep.link == "socket"  # their ticks on a Unix socket of their own
    assert load(quick, ["lockstep.link=zenoh"]).scenario.lockstep.link == "zenoh"
    said = r"lockstep\.link: expected one of 'socket' or 'zenoh'; got 'zenho' \(did you mean `zenoh`"
    with pytest.raises(ScenarioError, match=said):
        load(quick, ["lockstep.link=zenho"])


def test_strict_types_keep_what_is_right(write_scenario):
    """Strict mode refuses "40" and true for numbers, but an integer is a fine float, enum and
    literal names still read, and anchors, merge keys and dates work as YAML says."""
    text = BASE.replace("low: 0, high: 1}", "low: 0, high: 2}") + textwrap.dedent(
        """
        description: 2024-01-01
        lockstep: {pin_cpus: auto, spin_us: 0}
        timeouts: &t {ready: 5, request: 3}
        record: {body_every: 0, decisions: false}
        """
    )
    plan = load(write_scenario(textwrap.dedent(text)))
    s = plan.scenario
    assert s.space[0].high == 2.0 and isinstance(s.space[0].high, float)
    assert s.lockstep.pin_cpus == "auto" and s.timeouts.ready == 5.0
    assert s.description == "2024-01-01"  # dates stay text
    merged = BASE.replace(
        "protocol: {kind: learn, trials: 5}", "base: &p {kind: learn, trials: 5}\nprotocol: {<<: *p, trials: 7}"
    )
    with pytest.raises(ScenarioError, match="base: unknown key"):  # anchors and merges parse; the key is unknown
        load(write_scenario(merged))


def test_restart_on_failure_is_accepted_for_bodies_and_controllers_only_and_is_their_default(write_scenario):
    quick = SCENARIOS / "quickstart.yaml"
    defaults = {i.spec_name: i.restart for i in load(quick).instances}
    assert defaults == {
        "acc": "never",
        "vigilance": "never",
        "ofc": "never",
        "controller": "on-failure",
        "body": "on-failure",
    }
    assert {i.spec_name: i.restart for i in load(quick, ["modules.body.restart=never"]).instances}["body"] == "never"
    plan = load(quick, ["modules.body.restart=on-failure", "modules.controller.restart=on-failure"])
    assert {i.spec_name: i.restart for i in plan.instances} == {
        "acc": "never",
        "vigilance": "never",
        "ofc": "never",
        "controller": "on-failure",
        "body": "on-failure",
    }
    for brain in ("acc", "vigilance", "ofc"):
        with pytest.raises(ScenarioError) as info:
            load(quick, [f"modules.{brain}.restart=on-failure"])
        assert f"modules.{brain}.restart: expected 'never' for " in str(info.value)


def test_terrains_and_map_shapes_that_fit_pass_check():
    plan = load(SCENARIOS / "e3_5_fixed.yaml", ['conditions.body.terrain="1:0,2.5:-12.5,1:45"'])
    assert plan.scenario.conditions["body.terrain"] == "1:0,2.5:-12.5,1:45"
    assert load(SCENARIOS / "analytic_learn.yaml", ["modules.acc.params.shape=[64, 64]"])
    assert load(SCENARIOS / "analytic_learn.yaml", ["modules.acc.params.shape=[16, 16, 16]"])


def test_module_params_stay_lists_through_json_for_the_host():
    """The host re-validates params from JSON (``model_dump(mode='json')``): tuples arrive as lists."""
    from sfl_brain.registry import resolve

    plan = load(SCENARIOS / "quickstart.yaml", ["modules.acc.params.shape=[5, 6]"])
    acc = next(i for i in plan.instances if i.name == "acc")
    assert acc.params["shape"] == [5, 6]
    cls, _ = resolve(acc.reference)
    assert cls.Params.model_validate(acc.params).shape == (5, 6)


def test_sfl_list_prints_a_body_s_signal_table():
    done = sfl("list", "planar_biped")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert any(line.split()[:3] == ["hip_l", "rad", "[0.349066,"] for line in lines)
    assert any(line.split()[:4] == ["v_knee_r", "V", "[-12,", "12]"] for line in lines)
    assert "substeps = 10  physics steps per control tick" in done.stdout
    done = sfl("list", "reflex")
    assert "reads sensors:  hip_l, hip_r, knee_l, knee_r, contact_l, contact_r, slope" in done.stdout
    done = sfl("list", "cpg")  # its signals come from its circuit: the default one's are shown
    assert "reads sensors (with the default parameters):  hip_l, hip_r, knee_l" in done.stdout
    assert "writes commands (with the default parameters): v_hip_l, v_hip_r" in done.stdout
    done = sfl("list", "planar_bipd")
    assert done.returncode == 2 and "did you mean `planar_biped`" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize(
    ("setting", "says"),
    [
        ("protocol.proposer.kind=CMA", "got 'CMA' (did you mean `cma`?)"),  # case does not count
        ("modules.vigilance.params.mode=FIXED", "got 'FIXED' (did you mean `fixed`?)"),
        ("protocol.kind=Learn", "got 'Learn' (did you mean `learn`?)"),
        ("modules.acc.params.neighbourhod=thesis", "(did you mean `neighbourhood`?)"),
        (
            "protocol.proposer.kind=null",
            "protocol.proposer.kind: expected one of 'sfl', 'random', 'cma', 'tpe', 'safe_bo'; got null",
        ),
    ],
)
def test_suggestions_ignore_case_and_an_empty_value_reads_as_written(setting, says):
    with pytest.raises(ScenarioError) as err:
        load(SCENARIOS / "quickstart.yaml", [setting])
    text = str(err.value)
    assert says in text and "'None'" not in text


def test_sfl_list_gives_a_bodys_metric_units():
    done = sfl("list", "planar_biped")
    assert done.returncode == 0, done.stderr
    assert (
        "trial metrics (m_<metric> columns): distance (m), velocity (m/s), steps, time (s), energy (J), fell"
        in done.stdout
    )
