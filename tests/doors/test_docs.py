"""docs/write-a-body.md is run: its files are the example's files, its cart-pole body and balance
controller pass the conformance check, its commands print what the page shows, a real run of its
scenario learns with successes and failures and records the body, and a miswired controller is
refused naming both ends."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest
from rerun.chunk import RrdReader

from sfl_brain.body import InProcessLink
from sfl_brain.conformance import check_module
from sfl_brain.messages import TrialRequest
from sfl_brain.registry import resolve
from sfl_brain.telemetry import CaptureTelemetry, Rates

from ..conftest import ROOT, sfl

PAGE = ROOT / "docs" / "write-a-body.md"
EXAMPLE = ROOT / "docs" / "examples" / "cartpole"
SCENARIO = "docs/examples/cartpole/cartpole.yaml"
BODY = "docs/examples/cartpole/cartpole.py:CartPole"
CONTROLLER = "docs/examples/cartpole/balance.py:BalanceController"
#: the page shows the checkout as this folder
SHOWN_ROOT = "/home/me/sfl-brain"


def page() -> str:
    return PAGE.read_text()


def shown_output(command: str) -> str:
    """The output under ``$ COMMAND`` in the page's console block that starts with it."""
    for block in re.findall(r"```console\n(.*?)```", page(), re.S):
        first, _, rest = block.partition("\n")
        if first.startswith(f"$ {command}"):
            return rest.rstrip("\n")
    raise AssertionError(f"the page shows no `$ {command}`")


def output(done) -> str:
    """What a command printed, as the page shows it (the checkout's path as SHOWN_ROOT, no progress bar, no
    lockstep placement line: it names this machine's cores)."""
    text = (done.stdout + done.stderr).replace(str(ROOT), SHOWN_ROOT)
    lines = text.rstrip("\n").splitlines()
    return "\n".join(line for line in lines if "━" not in line and not line.startswith("sfl: lockstep placement"))


def test_the_page_shows_each_file_as_it_is():
    blocks = re.findall(r"<!-- file: (\S+) -->\n```\w+\n(.*?)```", page(), re.S)
    assert {path for path, _ in blocks} == {f"docs/examples/cartpole/{f.name}" for f in EXAMPLE.iterdir()}
    for path, text in blocks:
        assert text == (ROOT / path).read_text(), f"{PAGE.name}: the block of {path} differs from the file"


@pytest.mark.parametrize("impl", [BODY, CONTROLLER])
def test_the_body_and_the_controller_conform(impl):
    cls, _ = resolve(impl, ROOT)
    check_module(cls)


def test_the_pages_python_runs_as_shown(monkeypatch):
    blocks = re.findall(r"<!-- run by tests/doors/test_docs.py -->\n```python\n(.*?)```", page(), re.S)
    assert blocks, "the page marks no block to run"
    monkeypatch.chdir(ROOT)  # the page runs them from the checkout's root
    for block in blocks:
        exec(compile(block, str(PAGE), "exec"), {})


def test_a_trial_balances_or_falls_where_the_physics_says_and_a_logged_one_shows_it():
    body_cls, _ = resolve(BODY, ROOT)
    controller_cls, _ = resolve(CONTROLLER, ROOT)
    body = body_cls()
    body.link = InProcessLink(controller_cls())
    body.telemetry = CaptureTelemetry()  # the default rates: 25 samples and 25 pictures per simulated second

    def trial(trial_id, k_angle, k_spin):
        gains = {"k_angle": k_angle, "k_spin": k_spin}
        request = TrialRequest(trial_id=trial_id, seed=0, body_params={}, controller_params=gains, log=True)
        return body.handle(request)

    steady, limp, swinging = trial(0, 30.0, 5.0), trial(1, 5.0, 5.0), trial(2, 30.0, 0.5)
    assert steady.success and 0 < steady.quality < 1 and steady.metrics["time_up"] == pytest.approx(5.0)
    assert not limp.success and limp.metrics["fell"] and limp.quality == 0  # k_angle below (m_c + m_p) g
    assert not swinging.success and swinging.metrics["fell"]  # too little damping
    shown = body.telemetry
    angle = shown.at("angle")[0]
    assert angle.trial == 0 and angle.unit == "deg" and len(angle.times) == 125  # 5 s at 25 per s
    assert angle.times[0] == pytest.approx(0.01) and np.abs(angle.values).max() <= 12  # the pole stayed up
    assert [len(s.times) for s in shown.at("cart_x")] == [len(s.times) for s in shown.at("force")] == [125, 33, 25]
    picture = shown.at("picture")[1]
    assert picture.per_frame == 3 and len(picture.strips) == 3 * len(picture.times) == 3 * 33
    assert picture.times[0] == pytest.approx(5.01)  # trial 1 starts at 5 s on sim_time
    # the sink's rates decide what is kept: every tick's values, 10 pictures per second
    body.telemetry = CaptureTelemetry(rates=Rates(signals_hz=0, pictures_hz=10))
    trial(3, 30.0, 5.0)
    assert len(body.telemetry.at("angle")[0].times) == 500 and len(body.telemetry.at("picture")[0].times) == 50


def test_sfl_list_and_sfl_check_print_what_the_page_shows():
    for command in (f"list {BODY}", f"list {CONTROLLER}", f"check {SCENARIO}"):
        done = sfl(*command.split())
        assert done.returncode == 0, done.stderr
        assert output(done) == shown_output(f"sfl {command}")
    tilt = f"check {SCENARIO} --set conditions.body.tilt_deg=40"
    done = sfl(*tilt.split())
    assert done.returncode == 2 and output(done) == shown_output(f"sfl {tilt}")


def test_a_controller_reading_a_sensor_the_body_lacks_is_refused_naming_both_ends(tmp_path):
    copy = tmp_path / "cartpole"
    shutil.copytree(EXAMPLE, copy)
    balance = copy / "balance.py"
    balance.write_text(balance.read_text().replace('READS = ("angle"', 'READS = ("angel"'))
    done = sfl("check", "cartpole.yaml", cwd=copy)
    assert done.returncode == 2
    assert "controller `BalanceController` reads sensors angel (did you mean `angle`?)" in done.stderr
    assert "body `body` (CartPole) does not have" in done.stderr
    assert output(done) == shown_output("sfl check cartpole.yaml")


def test_the_scenario_runs_learns_with_successes_and_failures_and_records_the_body(tmp_path):
    out = tmp_path / "cartpole"
    done = sfl("run", SCENARIO, "--out", str(out), timeout=120)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["trials"] == 50
    trials = [json.loads(line) for line in (out / "records.jsonl").read_text().splitlines()]
    trials = [r for r in trials if r["kind"] == "trial"]
    assert len(trials) == 50 and 0 < sum(r["success"] for r in trials) < 50
    # what the page shows, but the wall time
    wall = re.compile(r"wall [\d.]+ s")
    shown = shown_output(f"sfl run {SCENARIO} --out runs/cartpole")
    assert wall.sub("wall", output(done).replace(str(out), "runs/cartpole")) == wall.sub("wall", shown)
    inspected = output(sfl("inspect", str(out))).splitlines()
    shown_lines = shown_output("sfl inspect runs/cartpole").splitlines()
    times = next(i for i, line in enumerate(shown_lines) if "wall_time_s" in line)  # from here on, times only
    assert inspected[:times] == shown_lines[:times]
    assert [line.split()[0] for line in inspected[times:]] == [line.split()[0] for line in shown_lines[times:]]
    # the recording holds the learning and, on sim_time, the body's cart and pole of every trial
    rows: dict[str, int] = {}
    for chunk in RrdReader(out / "recording.rrd").stream().to_chunks():
        rows[str(chunk.entity_path)] = rows.get(str(chunk.entity_path), 0) + chunk.num_rows
    assert rows["/trials/success"] == 50 and rows["/acc/success_map/neurons"] >= 50
    successes = sum(r["success"] for r in trials)
    assert rows["/body/picture"] >= 50 and rows["/body/angle"] >= 125 * successes  # 25 per s, 5 s each
    assert rows["/body/trial/events"] == 2 * 50  # each trial's start and end


def test_a_controller_knows_its_trial_and_tick_without_overriding_the_reset():
    body_cls, _ = resolve(BODY, ROOT)
    controller_cls, _ = resolve(CONTROLLER, ROOT)
    seen = []

    class Watching(controller_cls):
        def step(self, sensors):
            seen.append((self.trial.trial_id, self.trial.seed, self.trial.dt, self.tick))
            return super().step(sensors)

    controller = Watching()
    assert controller.trial is None and controller.tick == -1
    body = body_cls()
    body.link = InProcessLink(controller)
    for trial_id, seed in ((4, 11), (5, 12)):
        gains = {"k_angle": 30.0, "k_spin": 5.0}
        body.handle(TrialRequest(trial_id=trial_id, seed=seed, body_params={}, controller_params=gains, log=False))
    first = [s for s in seen if s[0] == 4]
    assert first[0] == (4, 11, body.params.control_dt, 0) and [s[3] for s in first] == list(range(len(first)))
    assert seen[len(first)] == (5, 12, body.params.control_dt, 0)  # the next trial starts again at tick 0
