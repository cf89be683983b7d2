"""Where a run's processes run: each body worker and its controller process share a core of their own,
brain modules the other cores (``sfl_brain.runtime.placement.place``, a pure function of the pairs, the usable
cores and ``lockstep.pin_cpus``)."""

from __future__ import annotations

import pytest

from sfl_brain.runtime.placement import Pair, Placement, cpu_list, place
from sfl_brain.runtime.supervisor import lockstep_pairs
from sfl_brain.scenario import load

from ..conftest import SCENARIOS

PAIR = [Pair("body", "controller")]
BRAIN = ["acc", "vigilance", "ofc"]
TWO = [Pair("body.0", "controller.0"), Pair("body.1", "controller.1")]


def test_on_one_core_nothing_is_pinned():
    placed = place(PAIR, BRAIN, [0], "auto")
    assert placed.cores == {} and placed.of("body") is None
    assert placed.reason == "nothing pinned: one usable core"
    assert place(PAIR, BRAIN, [3], "always").cores == {}


def test_on_two_cores_the_pair_shares_the_last_and_the_brain_modules_get_the_other():
    placed = place(PAIR, BRAIN, [0, 1], "auto")
    assert placed.cores == {"body": (1,), "controller": (1,), "acc": (0,), "vigilance": (0,), "ofc": (0,)}
    assert placed.of("controller") == [1]
    assert placed.describe() == (
        "lockstep placement (lockstep.pin_cpus: auto, usable cores 0-1): "
        "body and controller share core 1; acc, vigilance, ofc on core 0"
    )


def test_on_four_cores_each_pair_gets_a_core_from_the_last_and_the_brain_modules_the_rest():
    placed = place(TWO, BRAIN, [0, 1, 2, 3], "auto")
    assert placed.of("body.0") == placed.of("controller.0") == [3]
    assert placed.of("body.1") == placed.of("controller.1") == [2]
    assert placed.of("acc") == placed.of("ofc") == [0, 1]
    assert placed.reason.endswith("acc, vigilance, ofc on cores 0-1")


def test_a_taskset_mask_is_respected():
    """``taskset -c 2,5,7 sfl run``: only those cores, the pair on the last of them."""
    placed = place(PAIR, BRAIN, [7, 2, 5], "auto")
    assert placed.usable == (2, 5, 7)
    assert placed.of("body") == placed.of("controller") == [7]
    assert placed.of("vigilance") == [2, 5]
    assert all(core in (2, 5, 7) for cores in placed.cores.values() for core in cores)
    assert "usable cores 2,5,7" in placed.describe()


def test_as_many_pairs_as_cores_leave_the_brain_modules_unpinned():
    placed = place(TWO, BRAIN, [0, 1], "auto")
    assert placed.of("body.0") == [1] and placed.of("body.1") == [0]
    assert placed.of("acc") is None
    assert placed.reason.endswith("acc, vigilance, ofc not pinned (no core left)")


def test_more_pairs_than_cores_are_left_to_the_scheduler_unless_always():
    three = [Pair(f"body.{i}", f"controller.{i}") for i in range(3)]
    assert place(three, BRAIN, [0, 1], "auto").cores == {}
    assert "3 body-controller pairs on 2 cores" in place(three, BRAIN, [0, 1], "auto").reason
    shared = place(three, BRAIN, [0, 1], "always")
    assert [shared.of(f"controller.{i}") for i in range(3)] == [[1], [0], [1]]  # in turn


def test_never_no_affinity_and_colocated_controllers_pin_nothing():
    assert place(PAIR, BRAIN, [0, 1, 2, 3], "never").reason == "nothing pinned: lockstep.pin_cpus is never"
    assert place(PAIR, BRAIN, [], "auto").reason == "nothing pinned: this OS offers no CPU affinity"
    colocated = place([Pair("body.0", None), Pair("body.1", None)], BRAIN, [0, 1, 2, 3], "always")
    assert colocated.cores == {} and "no body worker has a controller process" in colocated.reason
    with pytest.raises(ValueError, match="lockstep.pin_cpus must be one of"):
        place(PAIR, BRAIN, [0, 1], "sometimes")


def test_the_placement_is_a_pure_function_and_reads_back_as_json():
    first, again = place(TWO, BRAIN, [0, 1, 2, 3], "auto"), place(TWO, BRAIN, [0, 1, 2, 3], "auto")
    assert first == again and isinstance(first, Placement)
    assert first.to_json()["cores"]["body.1"] == [2] and first.to_json()["usable_cores"] == [0, 1, 2, 3]


def test_core_lists_read_as_taskset_writes_them():
    assert cpu_list([0, 1, 2, 3, 6]) == "0-3,6"
    assert cpu_list([5]) == "5" and cpu_list([]) == "none" and cpu_list([3, 1, 2]) == "1-3"


def test_a_scenarios_pairs_are_its_body_workers_and_their_controller_processes():
    quick = SCENARIOS / "quickstart.yaml"
    assert load(quick).scenario.lockstep.pin_cpus == "auto"  # the default
    assert lockstep_pairs(load(quick)) == ([Pair("body", "controller")], BRAIN)
    pairs, others = lockstep_pairs(load(quick, ["modules.body.workers=2"]))
    assert pairs == TWO and others == BRAIN
    pairs, _ = lockstep_pairs(load(quick, ["modules.body.workers=2", "modules.controller.colocate=true"]))
    assert pairs == [Pair("body.0", None), Pair("body.1", None)]
    assert lockstep_pairs(load(SCENARIOS / "analytic_learn.yaml"))[0] == [Pair("body", None)]  # no controller


def test_auto_puts_the_pair_on_the_least_busy_core_and_no_module_on_a_busy_one():
    """Another process keeps the last core busy: the pair takes the quiet one, the brain modules are not trapped on
    the busy one (not pinned); with every core busy, nothing is pinned; ``always`` keeps its fixed order."""
    busy_last = place(PAIR, BRAIN, [0, 1], "auto", {0: 0.03, 1: 0.97})
    assert busy_last.of("body") == busy_last.of("controller") == [0] and busy_last.of("acc") is None
    assert "not pinned (the other cores are kept busy by other work)" in busy_last.reason
    assert busy_last.reason.endswith("other work on core 0 3%, core 1 97%")
    four = place(TWO, BRAIN, [0, 1, 2, 3], "auto", {0: 0.0, 1: 0.9, 2: 0.0, 3: 0.8})
    assert four.of("body.0") == [2] and four.of("body.1") == [0] and four.of("acc") is None
    everything = place(PAIR, BRAIN, [0, 1], "auto", {0: 0.7, 1: 0.97})
    assert everything.cores == {} and "other work keeps the cores busy (core 0 70%, core 1 97% of the time)" in (
        everything.reason
    )
    assert place(PAIR, BRAIN, [0, 1], "always", {0: 0.0, 1: 1.0}).of("body") == [1]
    # quiet cores, or loads within a tenth of each other: as before, the last core
    assert place(PAIR, BRAIN, [0, 1], "auto", {0: 0.02, 1: 0.04}).of("body") == [1]
    assert place(PAIR, BRAIN, [0, 1], "auto", {0: 0.0, 1: 0.0}) == place(PAIR, BRAIN, [0, 1], "auto", {0: 0, 1: 0})
