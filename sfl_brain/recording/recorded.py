"""Reading a run's recording back: the scalar series and text events a body or controller logged on ``sim_time``.

``sfl report`` draws what only the recording holds (a logged trial's torso pitch, its path, the pattern switches)
from ``recording.rrd``, the file a run leaves, with Rerun's own reader (:mod:`rerun.chunk`). A series is keyed by its
entity path as the viewer shows it (``body/torso/pitch``) and split by trial (the ``trial`` index every logged sample
carries); its time is ``sim_time`` in s (trial k of a run starts at k x the body's ``duration``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader


@dataclass
class Series:
    """One trial's samples of one scalar series: times (s of sim_time) and values, sorted by time."""

    times: np.ndarray
    values: np.ndarray


@dataclass
class Events:
    """One trial's text events: times (s of sim_time) and texts."""

    times: np.ndarray
    texts: list[str]


def _rows(path: Path, entities: set[str] | None):
    """(entity, record batch, column names) of every per-trial chunk at ``entities`` (None: at every entity)."""
    for chunk in RrdReader(Path(path)).stream().to_chunks():
        entity = str(chunk.entity_path).lstrip("/")
        if chunk.is_static or (entities is not None and entity not in entities):
            continue
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "sim_time" not in names or "trial" not in names:
            continue
        yield entity, batch, names


def read_series(path: Path, entities: list[str]) -> dict[str, dict[int, Series]]:
    """Every logged trial's samples of each scalar series in ``entities`` (paths without the leading ``/``):
    {entity: {trial: Series}}; an entity the recording lacks maps to {}."""
    found: dict[str, dict[int, list]] = {e: {} for e in entities}
    for entity, batch, names in _rows(path, set(entities)):
        if "Scalars:scalars" not in names:
            continue
        times = batch.column("sim_time").cast("int64").to_numpy() / 1e9
        trials = batch.column("trial").to_numpy()
        values = np.array([v[0] if v else np.nan for v in batch.column("Scalars:scalars").to_pylist()], dtype=float)
        for trial in np.unique(trials):
            mine = trials == trial
            found[entity].setdefault(int(trial), []).append((times[mine], values[mine]))
    out: dict[str, dict[int, Series]] = {}
    for entity, by_trial in found.items():
        out[entity] = {}
        for trial, parts in by_trial.items():
            times = np.concatenate([p[0] for p in parts])
            values = np.concatenate([p[1] for p in parts])
            order = np.argsort(times, kind="stable")
            out[entity][trial] = Series(times[order], values[order])
    return out


def read_events(path: Path, entities: list[str]) -> dict[str, dict[int, Events]]:
    """Every logged trial's text events at ``entities``: {entity: {trial: Events}}."""
    found: dict[str, dict[int, list]] = {e: {} for e in entities}
    for entity, batch, names in _rows(path, set(entities)):
        if "TextLog:text" not in names:
            continue
        times = batch.column("sim_time").cast("int64").to_numpy() / 1e9
        trials = batch.column("trial").to_numpy()
        texts = [t[0] if isinstance(t, list) and t else str(t) for t in batch.column("TextLog:text").to_pylist()]
        for k, trial in enumerate(trials):
            found[entity].setdefault(int(trial), []).append((times[k], texts[k]))
    out: dict[str, dict[int, Events]] = {}
    for entity, by_trial in found.items():
        out[entity] = {}
        for trial, items in by_trial.items():
            items.sort(key=lambda item: item[0])
            out[entity][trial] = Events(np.array([i[0] for i in items]), [i[1] for i in items])
    return out


def read_labels(path: Path, entities: list[str]) -> dict[str, str]:
    """The name each series was logged with, its unit included (``knee_l (deg)``), by entity; absent ones left out."""
    wanted, out = set(entities), {}
    for chunk in RrdReader(Path(path)).stream().to_chunks():
        entity = str(chunk.entity_path).lstrip("/")
        if not chunk.is_static or entity not in wanted:
            continue
        batch = chunk.to_record_batch()
        if "SeriesLines:names" in batch.schema.names:
            names = batch.column("SeriesLines:names").to_pylist()
            if names and names[0]:
                out[entity] = str(names[0][0])
    return out


def read_entity_paths(path: Path) -> set[str]:
    """The entity paths (without the leading ``/``) the recording logged per-trial samples at, on ``sim_time``."""
    return {entity for entity, _, _ in _rows(path, None)}
