"""A balance controller for the cart-pole: a proportional-derivative push on the pole's angle, with
a weak pull of the cart back to the middle of the track.

    force = k_angle * angle + k_spin * spin + k_x * cart_x + k_v * cart_v      (N)

The pole's gains are learnt: ``k_angle`` must beat gravity (above (m_cart + m_pole) g, about
11 N/rad) and ``k_spin`` must damp the swing. The cart's gains are fixed; they are positive too,
because to bring the cart back toward the middle the pole must first lean that way.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from sfl_brain.body import Controller
from sfl_brain.module import ModuleParams


class BalanceParams(ModuleParams):
    k_angle: float = Field(30.0, ge=0, description="N/rad (learnt)")
    k_spin: float = Field(5.0, ge=0, description="N s/rad (learnt)")
    k_x: float = Field(1.0, ge=0, description="N/m: pull of the cart toward the middle")
    k_v: float = Field(2.0, ge=0, description="N s/m: damping of the cart's motion")


class BalanceController(Controller):
    """PD balance of a pole on a cart: force from the pole's angle and spin (learnt gains)."""

    Params = BalanceParams
    READS = ("angle", "spin", "cart_x", "cart_v")
    WRITES = ("force",)
    TRIAL_PARAMS = ("k_angle", "k_spin")

    def configure(self, params: dict, seed: int) -> None:
        p = self.params
        k_angle = float(params.get("k_angle", p.k_angle))
        k_spin = float(params.get("k_spin", p.k_spin))
        self.gains = np.array([k_angle, k_spin, p.k_x, p.k_v])  # in READS order

    def step(self, sensors: np.ndarray) -> np.ndarray:
        return np.array([self.gains @ sensors])
