"""NaN and infinities are errors at the boundary: the codec, Module.handle and a body's trial
refuse them with an error naming the module, the message and the field, and a run whose module
produces one stops ``failed`` at once (over real processes at the end of this file)."""

from __future__ import annotations

import json
import math
import textwrap
import time

import numpy as np
import pytest

from sfl_brain import messages as m
from sfl_brain.body import Body, Controller, InProcessLink
from sfl_brain.module import Module, on
from sfl_brain.signals import Signal

from ..conftest import sfl_run

NAN, INF = math.nan, math.inf


# --- the codec ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "msg, text",
    [
        (
            m.Threshold(s_vig=NAN, low=0.0, high=0.0),
            "vigilance.threshold (Threshold): s_vig = nan, not a finite number",
        ),
        (m.Reward(rho=INF, eta_min=0.1, eta_max=0.2), "ofc.reward (Reward): rho = inf, not a finite number"),
        (m.Learn(v=np.array([0.1, -INF]), success=True, rho=1.0), r"acc.learn (Learn): v[1] = -inf"),
        (
            m.Evaluate(candidates=np.array([[0.0, 1.0], [NAN, 2.0]]), s_vig=0.1),
            r"acc.evaluate (Evaluate): candidates[1, 0] = nan",
        ),
        (
            m.TrialResult(trial_id=4, success=True, quality=0.5, metrics={"distance": 1.0, "energy": INF}, worker="b"),
            "body.result (TrialResult): metrics['energy'] = inf",
        ),
        (
            m.TrialRequest(trial_id=1, seed=2, body_params={"terrain": [0.0, NAN]}, controller_params={}, log=False),
            "body.trial (TrialRequest): body_params['terrain'][1] = nan",
        ),
        (
            m.ControllerReset(trial_id=1, seed=2, params={NAN: 1.0}, sensors=[], commands=[]),
            "controller.reset (ControllerReset): params (a key) = nan",
        ),
        (
            m.ControllerReset(trial_id=1, seed=2, params={}, sensors=[], commands=[], dt=INF),
            "controller.reset (ControllerReset): dt = inf",
        ),
        (
            m.SensorFrame(trial_id=1, tick=5, values=np.array([0.0, 1.0, NAN])),
            "controller.sensors (SensorFrame): values[2] = nan",
        ),
        (
            m.MotorCommand(trial_id=1, tick=5, values=np.array([INF, 0.0])),
            "body.command (MotorCommand): values[0] = inf",
        ),
        # not the packed layout (float32, 2-D): the msgpack path checks them the same way
        (
            m.MotorCommand(trial_id=1, tick=5, values=np.array([0, NAN], dtype=np.float32)),
            r"body.command (MotorCommand): values[1] = nan",
        ),
        (
            m.SensorFrame(trial_id=1, tick=5, values=np.array([[0.0], [INF]])),
            r"controller.sensors (SensorFrame): values[1, 0] = inf",
        ),
    ],
)
def test_decode_refuses_a_non_finite_field_and_names_it(msg, text):
    data = m.encode(msg)
    decoders = [m.decode, m.decoder_for(type(msg))]
    for decode in decoders:
        with pytest.raises(m.NonFiniteError) as caught:
            decode(data)
        assert str(caught.value).startswith(text), str(caught.value)
        assert caught.value.module is None and caught.value.message == m.message_name(type(msg))


def test_a_packed_error_carries_the_trial_and_tick_and_is_not_a_message_error():
    data = m.encode(m.MotorCommand(trial_id=7, tick=12, values=np.array([0.0, NAN])))
    with pytest.raises(m.NonFiniteError) as caught:
        m.decoder_for(m.MotorCommand)(data)
    error = caught.value
    assert (error.field, error.header) == ("values[1]", {"trial_id": 7, "tick": 12})
    assert math.isnan(error.value) and not isinstance(error, m.MessageError) and isinstance(error, ValueError)


def test_large_finite_values_pass_even_when_their_sum_overflows():
    for values in (np.array([1e308, 1e308, -1e308]), np.full(100, 1e308), np.array([5e-324, -0.0])):
        back = m.decode(m.encode(m.SensorFrame(trial_id=0, tick=0, values=values)))
        np.testing.assert_array_equal(back.values, values)
    m.check_finite(m.TrialResult(trial_id=0, success=False, quality=1e308, metrics={"a": [1e308, 1e308]}, worker=""))


def test_none_is_how_a_field_says_no_value():
    @m.message("test.maybe")
    class Maybe(m.Message, kw_only=True):
        x: float | None = None
        extra: dict = {}

    try:
        back = m.decode(m.encode(Maybe(x=None, extra={"best": None, "n": 3})))
        assert back.x is None and back.extra == {"best": None, "n": 3}
        with pytest.raises(m.NonFiniteError, match=r"test.maybe \(Maybe\): x = nan"):
            m.decode(m.encode(Maybe(x=NAN)))
    finally:
        m._REGISTRY.pop("test.maybe", None)


# --- Module.handle: what a module receives and replies -----------------------------------------


class NanVigilance(Module):
    """s_vig 0 until ``trial_index`` 3, then NaN."""

    @on(m.TrialDone)
    def trial_done(self, msg: m.TrialDone) -> m.Threshold:
        s_vig = NAN if msg.trial_index >= 3 else 0.0
        return m.Threshold(s_vig=s_vig, low=0.0, high=0.0)


def test_handle_refuses_a_non_finite_reply_and_names_the_module():
    vigilance = NanVigilance()
    vigilance.entity = "vigilance"
    done = m.TrialDone(trial_index=2, success=True, n_success=2, n_failure=0)
    assert vigilance.handle(done).s_vig == 0.0
    with pytest.raises(m.NonFiniteError) as caught:
        vigilance.handle(m.TrialDone(trial_index=3, success=True, n_success=3, n_failure=0))
    assert str(caught.value) == (
        "NanVigilance 'vigilance' replied vigilance.threshold (Threshold): s_vig = nan, not a finite number"
    )
    assert (caught.value.module, caught.value.role, caught.value.field) == (
        "NanVigilance 'vigilance'",
        "replied",
        "s_vig",
    )


def test_handle_refuses_a_non_finite_message_it_receives():
    class Echo(Module):
        @on(m.Grade)
        def grade(self, msg: m.Grade) -> m.Reward:
            raise AssertionError("the handler must not see a non-finite grade")

    echo = Echo()
    with pytest.raises(
        m.NonFiniteError, match=r"^Echo 'echo' received ofc.grade \(Grade\): eta = inf, not a finite number$"
    ):
        echo.handle(m.Grade(eta=INF))


def test_run_local_stops_at_the_first_non_finite_reply(tmp_path):
    from sfl_brain.protocols.local import run_local
    from sfl_brain.scenario import load

    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(ANALYTIC.format(vigilance="{impl: nan_modules.py:NanVigilance}", ofc="{impl: ofc}"))
    (tmp_path / "nan_modules.py").write_text(NAN_MODULES)
    for through_codec in (True, False):
        with pytest.raises(
            m.NonFiniteError, match=r"^NanVigilance 'vigilance' replied vigilance.threshold \(Threshold\): s_vig = nan"
        ):
            run_local(load(scenario), through_codec=through_codec)


# --- a body's trial: its sensors, its controller's commands, its outcome -----------------------


class Tiny(Body):
    """Three sensors, one command, ``ticks`` ticks; ``bad`` puts a value into a sensor or the outcome."""

    SENSORS = (
        Signal("x", "m", -10, 10, "position"),
        Signal("v", "m/s", -10, 10, "speed"),
        Signal("contact", "", 0, 1, "touching"),
    )
    COMMANDS = (Signal("u", "N", -1, 1, "push"),)

    def __init__(self, bad: tuple = (), ticks: int = 10) -> None:
        super().__init__()
        self.entity = "body.0"
        self.bad, self.ticks = bad, ticks

    def start_trial(self, request):
        self.tick = 0

    def sense(self):
        values = np.array([0.1 * self.tick, 1.0, 0.0])
        if self.bad and self.bad[0] == "sensor" and self.tick == self.bad[1]:
            values[self.bad[2]] = self.bad[3]
        return values

    def actuate(self, command):
        self.tick += 1

    @property
    def done(self):
        return self.tick >= self.ticks

    def outcome(self):
        metrics = {"distance": 0.1 * self.tick}
        if self.bad and self.bad[0] == "metric":
            metrics["energy"] = self.bad[1]
        return True, 1.0, metrics


class Nudge(Controller):
    """Command 0.5, or NaN from tick ``nan_at`` on."""

    WRITES = ("u",)

    def __init__(self, nan_at: int = -1) -> None:
        super().__init__()
        self.nan_at = nan_at

    def configure(self, params, seed):
        self.tick = 0

    def step(self, sensors):
        self.tick += 1
        return np.array([NAN if self.tick - 1 == self.nan_at else 0.5])


def trial(body: Body, controller=None, link=None) -> m.TrialResult:
    body.link = link or InProcessLink(controller or Nudge())
    return body.handle(m.TrialRequest(trial_id=4, seed=0, body_params={}, controller_params={}, log=False))


def test_a_clean_trial_runs_to_its_end():
    result = trial(Tiny())
    assert result.success and result.metrics == {"distance": pytest.approx(1.0)}


@pytest.mark.parametrize("index, value, signal", [(0, NAN, "x"), (2, -INF, "contact")])
def test_a_non_finite_sensor_value_names_the_body_and_the_signal(index, value, signal):
    with pytest.raises(m.NonFiniteError) as caught:
        trial(Tiny(bad=("sensor", 3, index, value)))
    assert str(caught.value) == (
        f"Tiny 'body.0' sensed controller.sensors (SensorFrame): values[{index}] ({signal}) = {value!r}, "
        "not a finite number"
    )
    assert caught.value.header == {"trial_id": 4, "tick": 3}


def test_a_non_finite_outcome_names_the_body_and_the_metric():
    with pytest.raises(
        m.NonFiniteError, match=r"^Tiny 'body.0' replied body.result \(TrialResult\): metrics\['energy'\] = inf"
    ):
        trial(Tiny(bad=("metric", INF)))


def test_a_colocated_controller_s_non_finite_command_names_the_controller():
    controller = Nudge(nan_at=5)
    controller.entity = "controller"
    with pytest.raises(m.NonFiniteError) as caught:
        trial(Tiny(), controller)
    assert str(caught.value) == (
        "Nudge 'controller' replied body.command (MotorCommand): values[0] = nan, not a finite number"
    )
    assert controller.tick == 6  # the body stopped at the bad tick


def test_a_remote_controller_s_non_finite_command_fails_the_trial_at_once():
    """As through BusLink: the command is encoded, and the body's decoder refuses it."""

    class Wire:
        controller = "controller.0"  # BusLink's controller instance name

        def __init__(self):
            self.remote = Nudge(nan_at=5)
            self.decode = m.decoder_for(m.MotorCommand)

        def reset(self, msg):
            self.remote.handle(m.decode(m.encode(msg)))

        def step(self, frame):
            return self.decode(m.encode(self.remote.handle(m.decode(m.encode(frame)))))

    link = Wire()
    with pytest.raises(m.NonFiniteError) as caught:
        trial(Tiny(), link=link)
    assert str(caught.value) == (
        "controller 'controller.0' sent body.command (MotorCommand): values[0] = nan, not a finite number"
    )
    assert link.remote.tick == 6 and caught.value.header == {"trial_id": 4, "tick": 5}


# --- over real processes: the run stops failed, at once ----------------------------------------

NAN_MODULES = textwrap.dedent('''
    """Modules that go wrong on purpose: NaN or an infinity after a few trials or ticks."""
    import math

    import numpy as np

    from sfl_brain.bodies.planar_biped import PlanarBiped
    from sfl_brain.modules.controllers.open_loop import OpenLoopController
    from sfl_brain.messages import Grade, Rejected, Reward, Threshold, TrialDone, VigilanceStart
    from sfl_brain.module import Module, on


    class NanVigilance(Module):
        """s_vig 0 until three trials are done, then NaN."""

        def threshold(self, s_vig=0.0):
            return Threshold(s_vig=s_vig, low=0.0, high=0.0)

        @on(VigilanceStart)
        def start(self, msg):
            return self.threshold()

        @on(TrialDone)
        def trial_done(self, msg):
            return self.threshold(math.nan if msg.trial_index >= 3 else 0.0)

        @on(Rejected)
        def rejected(self, msg):
            return self.threshold()


    class InfOFC(Module):
        """Every success earns an infinite reward."""

        @on(Grade)
        def grade(self, msg):
            return Reward(rho=math.inf, eta_min=msg.eta, eta_max=msg.eta)


    class NanAtTick5(OpenLoopController):
        """The open-loop controller, but v_hip_r is NaN at tick 5 of the second trial."""

        def configure(self, params, seed):
            super().configure(params, seed)
            self.trials = getattr(self, "trials", 0) + 1
            self.tick = 0

        def step(self, sensors):
            command = super().step(sensors)
            if self.trials == 2 and self.tick == 5:
                command[1] = math.nan
            self.tick += 1
            return command


    class NanKnee(PlanarBiped):
        """The walker, but its knee_r sensor reads NaN at tick 5 of the first trial."""

        def start_trial(self, request):
            super().start_trial(request)
            self.tick = 0

        def sense(self):
            values = super().sense()
            if self.tick == 5:
                values[3] = np.nan
            self.tick += 1
            return values
''')

ANALYTIC = """
name: nonfinite
seed: 3
protocol: {{kind: learn, trials: 40}}
space:
  - {{name: x, target: body.x, low: 0.0, high: 1.0}}
  - {{name: y, target: body.y, low: 0.0, high: 1.0}}
modules:
  acc: {{impl: acc, params: {{shape: [5, 5]}}}}
  vigilance: {vigilance}
  ofc: {ofc}
  body: {{impl: analytic}}
"""

WALKER = """
name: nonfinite_walker
seed: 3
protocol: {{kind: learn, trials: 10}}
space:
  - {{name: amplitude, target: controller.amplitude, low: 1.0, high: 3.0}}
  - {{name: frequency, target: controller.frequency, low: 0.5, high: 1.5}}
modules:
  acc: {{impl: acc, params: {{shape: [5, 5]}}}}
  vigilance: {{impl: vigilance, params: {{mode: fixed, value: -1.0}}}}
  ofc: {{impl: ofc}}
  controller: {controller}
  body: {body}
timeouts: {{tick: 120}}
record: {{body_every: 0}}
"""


def failed_run(tmp_path, scenario_text: str) -> tuple[dict, list[dict], float]:
    """Run ``scenario_text`` (next to NAN_MODULES) with ``sfl run``; the summary, the trial rows and
    the wall time. The run must end failed with exit code 1."""
    from sfl_brain.recording.records import read_records

    (tmp_path / "nan_modules.py").write_text(NAN_MODULES)
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(scenario_text)
    out = tmp_path / "run"
    started = time.monotonic()
    done = sfl_run(scenario, out, timeout=240)
    wall = time.monotonic() - started
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["status"], done.returncode) == ("failed", 1), (done.stdout, done.stderr)
    assert " ".join(summary["stop_reason"].split()) in " ".join((done.stdout + done.stderr).split())  # shown
    return summary, [r for r in read_records(out) if r["kind"] == "trial"], wall


def test_run_stops_failed_when_a_user_vigilance_answers_nan(tmp_path):
    summary, trials, _ = failed_run(
        tmp_path, ANALYTIC.format(vigilance="{impl: nan_modules.py:NanVigilance}", ofc="{impl: ofc}")
    )
    assert "NanVigilance 'vigilance' replied vigilance.threshold (Threshold): s_vig = nan" in summary["stop_reason"]
    # the third trial's row is written once the vigilance has answered for it, which it did not
    assert len(trials) == 2 and summary["decisions"] < 10  # not two million no-go decisions


def test_run_stops_failed_when_a_user_ofc_answers_an_infinite_reward(tmp_path):
    summary, trials, _ = failed_run(
        tmp_path,
        ANALYTIC.format(
            vigilance="{impl: vigilance, params: {mode: fixed, value: -1.0}}", ofc="{impl: nan_modules.py:InfOFC}"
        ),
    )
    assert "InfOFC 'ofc' replied ofc.reward (Reward): rho = inf, not a finite number" in summary["stop_reason"]
    assert len(trials) <= 1 and summary["trials"] <= 1  # the first success is graded, and the run stops


@pytest.mark.parametrize("colocate", [False, True], ids=["controller-process", "colocated"])
def test_run_stops_failed_when_a_controller_commands_nan(tmp_path, colocate):
    controller = "{impl: nan_modules.py:NanAtTick5" + (", colocate: true}" if colocate else "}")
    summary, trials, wall = failed_run(tmp_path, WALKER.format(controller=controller, body="{impl: planar_biped}"))
    who = "NanAtTick5 'controller' replied" if colocate else "controller 'controller' sent"
    assert f"{who} body.command (MotorCommand): values[1] = nan, not a finite number" in summary["stop_reason"]
    assert len(trials) == 1  # the second trial failed at its tick 5: not retried, not counted
    assert wall < 120  # no tick timeout (120 s) was waited for


def test_run_stops_failed_when_a_body_senses_nan(tmp_path):
    summary, trials, _ = failed_run(
        tmp_path, WALKER.format(controller="{impl: open_loop}", body="{impl: nan_modules.py:NanKnee}")
    )
    assert (
        "NanKnee 'body' sensed controller.sensors (SensorFrame): values[3] (knee_r) = nan, not a finite number"
        in summary["stop_reason"]
    )
    assert trials == []
