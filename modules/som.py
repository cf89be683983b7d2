"""Kohonen self-organising map, as the thesis uses it (eqs. 2.7-2.11 and 5.1).

Weights live in the unit hypercube [0, 1]^dim. The learning rate and the
neighbourhood radius decay with the number of samples *this map* has learnt
(a success map and a failure map learn at different paces).
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from sfl_brain.module import ModuleParams


class SOMParams(ModuleParams):
    """Shape and schedule of a self-organising map."""

    shape: tuple[Annotated[int, Field(ge=1, le=1000)], ...] = Field(
        (10, 10), min_length=1, max_length=4, description="neuron grid"
    )
    learning_rate: float = Field(0.4, gt=0, le=1, description="epsilon at the first sample (2.10)")
    learning_rate_min: float = Field(0.02, ge=0, le=1, description="floor of epsilon")
    radius: float | None = Field(
        None, gt=0, description="sigma at the first sample, grid units (default: half the longest grid side)"
    )
    radius_min: float = Field(0.5, gt=0, description="floor of sigma, grid units")
    decay: float = Field(100.0, gt=0, description="samples for epsilon and sigma to fall by 1/e")
    neighbourhood: Literal["gaussian", "thesis"] = Field(
        "gaussian",
        description="'gaussian': exp(-|r-s|^2 / 2 sigma^2); 'thesis': exp(-|r-s| / 2 sigma^2) "
        "as printed in (2.11), so wide that a map stays contracted for hundreds of samples",
    )

    @model_validator(mode="after")
    def _fits_in_memory(self):
        size = int(np.prod(self.shape, dtype=object))
        if size > MAX_NEURONS:
            raise ValueError(
                f"expected at most {MAX_NEURONS} neurons (e.g. 64 x 64 or 16 x 16 x 16); shape "
                f"{list(self.shape)} has {size}, and its success and failure maps would need about "
                f"{_bytes(map_memory(self.shape))} of memory for their grid distances"
            )
        return self


#: neurons per map at most: a map keeps the grid distance between every pair of its neurons
#: (neurons^2 float64), so 4096 neurons take about 1 GB while a pair of 2-D maps is built
MAX_NEURONS = 4096


def map_memory(shape) -> int:
    """Bytes at the peak of building a success and a failure map of ``shape``: the first map's
    neurons^2 distance table plus the second's, with its per-axis differences and squares."""
    size = int(np.prod(shape, dtype=object))
    return size * size * 8 * (3 + 2 * len(shape))


def _bytes(n: int) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if n < 1000:
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} EB"


class SelfOrganisingMap:
    """A map of ``prod(shape)`` neurons with weights in [0, 1]^dim."""

    def __init__(self, params: SOMParams, dim: int, rng: np.random.Generator) -> None:
        self.params = params
        self.dim = dim
        self.shape = tuple(params.shape)
        self.size = int(np.prod(self.shape))
        #: grid coordinates of each neuron, shape (size, len(shape))
        self.grid = np.indices(self.shape).reshape(len(self.shape), -1).T.astype(float)
        self.weights = rng.random((self.size, dim))
        #: how many samples each neuron has won while learning
        self.wins = np.zeros(self.size, dtype=np.int64)
        #: neurons taking part in evaluation (pruning switches some off)
        self.active = np.ones(self.size, dtype=bool)
        self.samples = 0
        #: the reward each neuron has learnt (QARL, Fig. 5.9): the mean of the successes' eta weighted by how far
        #: each pulled the neuron (min(gamma h rho, 1) of (5.1)); reward_weight 0: none yet
        self.reward_sum = np.zeros(self.size)
        self.reward_weight = np.zeros(self.size)
        self._radius0 = params.radius if params.radius is not None else max(self.shape) / 2.0
        # grid distances between every pair of neurons, for the neighbourhood (2.11)
        diff = self.grid[:, None, :] - self.grid[None, :, :]
        self._grid_distance = np.sqrt((diff**2).sum(-1))
        if params.neighbourhood == "gaussian":
            self._grid_distance = self._grid_distance**2

    # --- schedule ----------------------------------------------------------------
    def learning_rate(self) -> float:
        """epsilon(n) = max(eps_min, eps_0 exp(-n / decay)), n = samples learnt so far."""
        p = self.params
        return max(p.learning_rate_min, p.learning_rate * np.exp(-self.samples / p.decay))

    def radius(self) -> float:
        """sigma(n) = max(sigma_min, sigma_0 exp(-n / decay)), in grid units."""
        p = self.params
        return max(p.radius_min, self._radius0 * np.exp(-self.samples / p.decay))

    # --- evaluation ----------------------------------------------------------------
    def distances(self, vectors: np.ndarray) -> np.ndarray:
        """|v - w_i| for every row v and active neuron i (3.1); shape (k, active)."""
        diff = vectors[:, None, :] - self.weights[self.active][None, :, :]
        return np.sqrt(np.einsum("kij,kij->ki", diff, diff))

    def nearest(self, vectors: np.ndarray) -> np.ndarray:
        """Distance from each row to its winner neuron (3.2)."""
        return self.distances(vectors).min(axis=1)

    def winner(self, v: np.ndarray) -> int:
        """Index of the neuron whose weights are closest to v (2.7-2.8)."""
        diff = self.weights - v
        d = np.einsum("ij,ij->i", diff, diff)
        d[~self.active] = np.inf
        return int(np.argmin(d))

    # --- learning ------------------------------------------------------------------
    def update(self, v: np.ndarray, rho: float = 1.0, eta: float | None = None) -> float:
        """Learn v: w_i += min(eps h_ci rho, 1) (v - w_i)  (2.9-2.11, 5.1). Returns sum of squared changes. ``eta``: the
        trial's quality, which each neuron learns with the same weight as v (``learnt_reward``)."""
        s = self.winner(v)
        sigma = self.radius()
        h = np.exp(-self._grid_distance[s] / (2.0 * sigma**2))  # (2.11)
        # (2.10), (5.1); gamma h rho at most 1 (CPG-HUMANOID.md §7.15): rho up to 2.5 must not carry a neuron past v
        step = np.minimum((self.learning_rate() * rho) * h, 1.0)
        delta = step[:, None] * (v - self.weights)
        if eta is not None:
            self.reward_sum += step * eta
            self.reward_weight += step
        self.weights += delta  # (2.9)
        self.wins[s] += 1
        self.samples += 1
        return float(np.einsum("ij,ij->", delta, delta))

    def learnt_reward(self) -> np.ndarray:
        """Each neuron's learnt reward: the eta of the successes it learnt, weighted as it learnt them (NaN: none)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.reward_weight > 0, self.reward_sum / self.reward_weight, np.nan)

    def segments(self, weights: np.ndarray | None = None) -> np.ndarray:
        """Every grid edge as a segment, shape (..., edges, 2, dim): the mesh in one array (fast to log).

        ``weights`` defaults to this map's; a stack of snapshots, shape (k, size, dim), gives k meshes.
        """
        w = self.weights if weights is None else weights
        lead = w.shape[:-2]
        w = w.reshape(*lead, *self.shape, self.dim)
        parts = []
        for axis in range(len(self.shape)):
            moved = np.moveaxis(w, len(lead) + axis, -2)  # (..., other axes, this axis, dim)
            pairs = np.stack([moved[..., :-1, :], moved[..., 1:, :]], axis=-2)
            parts.append(pairs.reshape(*lead, -1, 2, self.dim))
        return np.concatenate(parts, axis=-3)
