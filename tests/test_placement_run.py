"""A run places its lockstep pair and says so: real processes, the placement the OS reports, the link."""

from __future__ import annotations

import json
import os

import pytest

from sfl_brain.local import run_local
from sfl_brain.placement import Pair, place, usable_cpus
from sfl_brain.records import read_records
from sfl_brain.scenario import load

from .conftest import SCENARIOS, sfl_run

QUICK = SCENARIOS / "quickstart.yaml"
SETS = ("protocol.trials=6", "record.body_every=0", "modules.body.params.duration=3")
VOLATILE = {"wall_ms", "worker"}


def stable(rows):
    return [{k: v for k, v in r.items() if k not in VOLATILE} for r in rows]


def logs(out) -> dict[str, str]:
    return {p.stem: p.read_text() for p in (out / "logs").glob("*.log")}


def test_a_run_pins_its_pair_to_one_core_logs_it_and_ticks_on_its_lockstep_link(tmp_path):
    out = tmp_path / "run"
    done = sfl_run(QUICK, out, *SETS)
    assert done.returncode == 0, done.stderr
    expected = place([Pair("body", "controller")], ["acc", "vigilance", "ofc"], usable_cpus(), "auto")
    assert f"sfl: {expected.describe()}" in done.stdout.splitlines()  # the line a user sees
    placed = json.loads((out / "logs" / "placement.json").read_text())
    assert placed["cores"] == {name: list(cores) for name, cores in expected.cores.items()}
    assert placed["mode"] == "auto" and placed["usable_cores"] == usable_cpus()
    text = logs(out)
    if len(usable_cpus()) >= 2:  # as the OS says: both on the last usable core, the brain modules elsewhere
        core = usable_cpus()[-1]
        assert f"pinned to cores [{core}]" in text["body"] and f"pinned to cores [{core}]" in text["controller"]
        assert f"pinned to cores {usable_cpus()[:-1]}" in text["acc"]
    # the frames and commands went over the pair's own link: the controller listens, the body connects
    link = placed["lockstep_links"]["controller"]["listen"][0]
    assert placed["lockstep_links"]["body"] == {"connect": [link]} and link.startswith("unixsock-stream/")
    assert f"lockstep link (lowlatency): listening on {link}" in text["controller"]
    assert f"lockstep link (lowlatency): connecting to {link}" in text["body"]
    assert not os.path.exists(os.path.dirname(link.removeprefix("unixsock-stream/")))  # removed with the run
    # over processes, the same trials as in one process
    assert stable(read_records(out)) == stable(run_local(load(QUICK, list(SETS))))


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this OS")
def test_a_run_limited_to_one_core_by_taskset_pins_nothing(tmp_path):
    out = tmp_path / "run"
    core = usable_cpus()[-1]
    done = sfl_run(QUICK, out, *SETS, preexec_fn=lambda: os.sched_setaffinity(0, {core}))
    assert done.returncode == 0, done.stderr
    line = f"sfl: lockstep placement (lockstep.pin_cpus: auto, usable cores {core}): nothing pinned: one usable core"
    assert line in done.stdout.splitlines()
    assert all("pinned to cores" not in text for text in logs(out).values())
    assert json.loads((out / "logs" / "placement.json").read_text())["cores"] == {}
