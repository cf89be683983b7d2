"""ACC: success and failure maps with the early-warning go/no-go decision (thesis §3.3).

The success map S_m learns the parameter vectors of successful trials, the
failure map F_m those of failed trials. A candidate v is evaluated by its
distance to the winner of each map (3.1)-(3.2); the early warning signal (3.3)
vetoes it unless d_f - d_s > s_vig.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from pydantic import Field

from sfl_brain.messages import (
    Ack,
    Evaluate,
    Evaluation,
    Exploit,
    ExploitTable,
    Finish,
    Learn,
    Learned,
)
from sfl_brain.module import Module, on
from sfl_brain.telemetry import FAILURE, SUCCESS, MapSnapshots, MapWinners

from .som import SelfOrganisingMap, SOMParams


class ACCParams(SOMParams):
    dim: int | None = Field(
        None,
        ge=1,
        le=8,
        description="dimension of the parameter space (default: the scenario's number of axes)",
    )
    restore: str | None = Field(None, description="a checkpoint (.npz) to start from")


class ACC(Module):
    """Success/failure self-organising maps and the early-warning decision (eqs. 3.1-3.3)."""

    Params = ACCParams

    def reset(self, seed: int) -> None:
        p = self.params
        dim = p.dim or len(p.shape)
        success_rng, failure_rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
        self.success_map = SelfOrganisingMap(p, dim, success_rng)
        self.failure_map = SelfOrganisingMap(p, dim, failure_rng)
        if p.restore:
            self.restore(p.restore)
        self._snapshots: list[tuple[int, dict]] = []  # map states not yet emitted as telemetry
        self._winners: list[tuple[int, dict]] = []  # each trial's winner of each map, not yet emitted
        self._flushed = time.monotonic()

    # --- evaluation and decision -------------------------------------------------
    def evaluate(self, candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """d_s and d_f for each row of ``candidates`` (3.1)-(3.2)."""
        return self.success_map.nearest(candidates), self.failure_map.nearest(candidates)

    @staticmethod
    def early_warning(d_success: np.ndarray, d_failure: np.ndarray, s_vig: float) -> np.ndarray:
        """EWS (3.3): True (no-go) unless d_f - d_s > s_vig."""
        return ~((d_failure - d_success) > s_vig)

    @on(Evaluate)
    def on_evaluate(self, msg: Evaluate) -> Evaluation:
        candidates = np.asarray(msg.candidates, dtype=float).reshape(-1, self.success_map.dim)
        d_s, d_f = self.evaluate(candidates)
        return Evaluation(d_success=d_s, d_failure=d_f, go=~self.early_warning(d_s, d_f, msg.s_vig))

    # --- learning --------------------------------------------------------------------
    def learn(self, v: np.ndarray, success: bool, rho: float = 1.0, eta: float | None = None) -> float:
        """A success teaches S_m with reward rho (5.1), and its quality eta as the neurons' learnt reward; a failure
        teaches F_m."""
        if success:
            return self.success_map.update(v, rho, eta)
        return self.failure_map.update(v, 1.0)

    @on(Learn)
    def on_learn(self, msg: Learn) -> Learned:
        v = np.asarray(msg.v, dtype=float)
        winners = self.success_map.winner(v), self.failure_map.winner(v)  # before learning: the maps that judged v
        if self.telemetry is not None:  # trial index (samples so far), each map's winner and where it stood
            trial = self.success_map.samples + self.failure_map.samples
            self._winners.append(
                (trial, {name: (n, m.weights[n].copy()) for (name, m), n in zip(self._maps(), winners, strict=True)})
            )
        change = self.learn(v, msg.success, msg.rho, msg.eta)
        if self.telemetry is not None:
            self.defer(self.log_maps)  # after the reply: showing the maps is off the learning cycle's path
        return Learned(
            change=change,
            n_success_samples=self.success_map.samples,
            n_failure_samples=self.failure_map.samples,
            success_winner=winners[0],
            failure_winner=winners[1],
        )

    # --- after learning ----------------------------------------------------------------
    def prune_failure_map(self) -> np.ndarray:
        """Switch off failure neurons that never won a failure sample and sit in the success zone.

        "In the success zone": closer to the success map than to any failure neuron that did
        represent failures (thesis §4.4.3, Fig. 4.13). Returns the indices removed.
        """
        fm = self.failure_map
        used = fm.wins > 0
        if not used.any():
            return np.array([], dtype=int)
        candidates = np.flatnonzero(~used & fm.active)
        if candidates.size == 0:
            return candidates
        w = fm.weights[candidates]
        d_success = self.success_map.nearest(w)
        diff = w[:, None, :] - fm.weights[used][None, :, :]
        d_failure = np.sqrt((diff**2).sum(-1)).min(axis=1)
        removed = candidates[d_success < d_failure]
        fm.active[removed] = False
        return removed

    def exploit(self, axis: int, conditions: np.ndarray) -> np.ndarray:
        """For each condition, the success neuron whose weight on ``axis`` is closest (§3.5.2)."""
        w = self.success_map.weights[self.success_map.active]
        idx = np.argmin(np.abs(w[None, :, axis] - np.asarray(conditions)[:, None]), axis=1)
        return w[idx]

    @on(Exploit)
    def on_exploit(self, msg: Exploit) -> ExploitTable:
        conditions = np.asarray(msg.conditions, dtype=float)
        return ExploitTable(conditions=conditions, weights=self.exploit(msg.axis, conditions))

    def checkpoint(self, path: str | Path) -> None:
        np.savez(
            path,
            **{f"{name}_{key}": getattr(m, key) for name, m in self._maps() for key in ("weights", "wins", "active")},
            success_reward=self.success_map.learnt_reward(),  # the eta each success neuron learnt (NaN: none)
            success_reward_sum=self.success_map.reward_sum,
            success_reward_weight=self.success_map.reward_weight,
            success_samples=self.success_map.samples,
            failure_samples=self.failure_map.samples,
        )

    def restore(self, path: str | Path) -> None:
        with np.load(path) as data:
            for name, m in self._maps():
                if data[f"{name}_weights"].shape != m.weights.shape:
                    raise ValueError(
                        f"{path}: {name} map has shape {data[f'{name}_weights'].shape}, this ACC has {m.weights.shape}"
                    )
                m.weights = data[f"{name}_weights"].copy()
                m.wins = data[f"{name}_wins"].copy()
                m.active = data[f"{name}_active"].copy()
            self.success_map.samples = int(data["success_samples"])
            self.failure_map.samples = int(data["failure_samples"])
            if "success_reward_sum" in data.files:  # checkpoints from before QARL's learnt rewards have none
                self.success_map.reward_sum = data["success_reward_sum"].copy()
                self.success_map.reward_weight = data["success_reward_weight"].copy()

    @on(Finish)
    def on_finish(self, msg: Finish) -> Ack:
        path = self._checkpoint_path(msg.path) if msg.path else None  # refused before anything changes
        removed = self.prune_failure_map() if msg.prune else np.array([], dtype=int)
        if path is not None:
            self.checkpoint(path)
        if self.telemetry is not None:
            self.flush_maps()
            self.log_maps()
            self.flush_maps(final=True)
        return Ack(detail=f"pruned {removed.size} failure neurons: {removed.tolist()}")

    def _checkpoint_path(self, path: str) -> Path:
        """Where ``Finish.path`` may be written: inside the run folder (``self.run_dir``, set by the
        host), relative paths resolved against it; anything that escapes it (``..``, an absolute
        path elsewhere, a symlink out) is refused. Without a run folder (in-process use) as given."""
        run_dir = getattr(self, "run_dir", None)
        target = Path(path)
        if target.suffix != ".npz":
            target = target.with_name(target.name + ".npz")  # what np.savez writes
        if run_dir is None:
            return target
        root = Path(run_dir).resolve()
        resolved = (root / target).resolve()  # an absolute target stays itself; symlinks are followed
        if not resolved.is_relative_to(root) or resolved == root:
            raise ValueError(f"acc.finish: refusing to write {path!r}: outside the run folder {root}")
        return resolved

    def _maps(self):
        return (("success", self.success_map), ("failure", self.failure_map))

    # --- observability ---------------------------------------------------------------------
    #: map snapshots are emitted in batches, at most this many trials or seconds late
    LOG_BATCH = 32
    LOG_SECONDS = 2.0
    COLOURS = {"success": SUCCESS, "failure": FAILURE}

    def log_maps(self) -> None:
        """Snapshot both maps (weights, active flags) after this trial; emitted in batches (see flush_maps)."""
        trial = self.success_map.samples + self.failure_map.samples
        self._snapshots.append(
            (trial, {name: (m.weights.copy(), m.active.copy(), m.learnt_reward()) for name, m in self._maps()})
        )
        if len(self._snapshots) >= self.LOG_BATCH or time.monotonic() - self._flushed > self.LOG_SECONDS:
            self.flush_maps()

    def flush_maps(self, final: bool = False) -> None:
        """Emit the buffered snapshots as :class:`~sfl_brain.telemetry.MapSnapshots`, one per map
        (``success_map``, ``failure_map``): neurons, active flags and grid edges after each trial, on
        the ``trial`` timeline (the number of trials learnt). ``final``: the maps as the run leaves them. Before them,
        each learnt trial's winner of each map (:class:`~sfl_brain.telemetry.MapWinners`)."""
        snapshots, self._snapshots = self._snapshots, []
        winners, self._winners = self._winners, []
        self._flushed = time.monotonic()
        if self.telemetry is not None and winners:  # each trial's winners over the snapshot they won in
            trials = np.array([t for t, _ in winners])
            for name, _ in self._maps():
                neurons = np.array([w[name][0] for _, w in winners])
                positions = np.stack([w[name][1] for _, w in winners])
                self.telemetry.emit(MapWinners(f"{name}_map", trials, neurons, positions, self.COLOURS[name]))
        if not snapshots or self.telemetry is None:
            return
        trials = np.array([t for t, _ in snapshots])
        for name, m in self._maps():
            weights = np.stack([snap[name][0] for _, snap in snapshots])
            active = np.stack([snap[name][1] for _, snap in snapshots])
            reward = np.stack([snap[name][2] for _, snap in snapshots]) if name == "success" else None
            if reward is not None and not np.isfinite(reward).any():
                reward = None  # nothing graded (no OFC, or no success yet): the map's own colour
            self.telemetry.emit(
                MapSnapshots(
                    f"{name}_map", trials, weights, active, m.segments(weights), self.COLOURS[name], final, reward
                )
            )

    def close(self) -> None:
        self.flush_maps()
