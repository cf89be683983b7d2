"""The conformance check passes every registered module, and fails modules that break the contract."""

import random

import numpy as np
import pytest
from pydantic import BaseModel

from sfl_brain import messages as m
from sfl_brain.bodies.planar_biped import SENSORS, PlanarBiped
from sfl_brain.body import Controller
from sfl_brain.conformance import check_module
from sfl_brain.module import Module, on
from sfl_brain.modules.controllers.open_loop import OpenLoopController
from sfl_brain.modules.ofc import OFC
from sfl_brain.registry import registered, resolve
from sfl_brain.signals import Signal


@pytest.mark.parametrize("name", sorted(registered()))
def test_every_registered_module_conforms(name):
    cls, _ = resolve(name)
    check_module(cls)


class NarrowHips(PlanarBiped):
    SENSORS = (Signal("hip_l", "rad", 0.0, 0.1, "a range the walker's hip leaves"), *SENSORS[1:])


class NamesOnly(PlanarBiped):
    SENSORS = tuple(s.name for s in SENSORS)


class ShortController(OpenLoopController):
    def step(self, sensors):
        return np.zeros(3)


class Moody(OFC):
    """Replies depend on a global random number, not on the seed."""

    @on(m.Grade)
    def grade(self, msg):
        return m.Reward(rho=random.random(), eta_min=0.0, eta_max=1.0)


class Unfrozen(Module):
    class Params(BaseModel):
        x: float = 1.0

    @on(m.Grade)
    def grade(self, msg):
        return m.Reward(rho=1.0, eta_min=0.0, eta_max=1.0)


class NoWrites(Controller):
    def configure(self, params, seed):
        pass


@pytest.mark.parametrize(
    "cls, says",
    [
        (NarrowHips, "NarrowHips: sensor hip_l = "),
        (NamesOnly, "NamesOnly.SENSORS must be Signals"),
        (ShortController, "ShortController: returned 3 commands for 4 WRITES"),
        (Moody, "Moody: same seed gave different replies"),
        (Unfrozen, "Unfrozen.Params must be frozen"),
        (NoWrites, "NoWrites: a controller declares the commands it WRITES"),
    ],
)
def test_the_check_fails_a_module_that_breaks_the_contract(cls, says):
    with pytest.raises(AssertionError) as info:
        check_module(cls)
    assert says in str(info.value)
