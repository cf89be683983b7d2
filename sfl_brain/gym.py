"""A scenario's body, controller and parameter space as Gymnasium environments (``pip install 'sfl-brain[gym]'``).

Two doors, registered with Gymnasium when this module is imported (:func:`register_envs`); docs/gymnasium.md shows
both, with a CMA-ES loop that runs:

- ``sfl/Trial-v0`` (:class:`TrialEnv`): one episode is one trial. The action is a point of the scenario's parameter
  space in the unit cube, mapped to physical parameters by the plan (``Plan.to_physical``, as the protocols map every
  point they try); ``step`` runs the whole trial on the body and its controller in this process (``Body.trial``, the
  lockstep loop of every run) and rewards the trial's quality eta when it succeeds. A black-box optimiser sees the
  scenario as the success and failure maps see it.
- ``sfl/Tick-v0`` (:class:`TickEnv`): one step is one control tick, for reinforcement learning. The agent is the
  controller: the action is the body's commands, the observation its sensors, as the body declares them
  (``Body.COMMANDS``, ``Body.SENSORS``: units and ranges in ``sfl list BODY``).

Spaces are float32 (what RL libraries expect; an action given as float64 is used at full precision). With
``normalize=True`` an environment takes its actions in [-1, 1] and gives its observations scaled by the body's
declared ranges: what Gymnasium's and stable-baselines3's checkers recommend, with no wrapper.

``sfl/Trial-v0`` declares ``metadata["autoreset_mode"] = SAME_STEP`` and has a vector entry point
(:func:`make_trial_vector`), so ``gymnasium.make_vec("sfl/Trial-v0", num_envs=N)`` runs a trial in every env on every
step (under Gymnasium's default ``NEXT_STEP``, every other step would be a reset that runs no trial).

Episode k after ``reset(seed=s)`` is trial k of a run with seed s: the same trial seed (``protocols.trial_seed``,
as ``Conductor.trial_request`` gives it) and the same module seeds (``scenario.instance_seed``), so a trial gives here
what ``sfl run --seed s`` or ``protocols.local`` gives for the same parameters. Before any seeded reset, s is the
scenario's seed (or the constructor's ``seed``, as ``sfl run --seed``).

Nothing else in sfl_brain imports this module, so the core does not need Gymnasium.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

try:
    import gymnasium
    from gymnasium import spaces
    from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv
except ImportError as exc:  # the core does not need it; this door does
    raise ImportError("sfl_brain.gym needs Gymnasium: pip install 'sfl-brain[gym]' (gymnasium>=1.0)") from exc

from .body import Body, _finite_vector
from .messages import TrialRequest
from .protocols.conductor import trial_seed
from .protocols.local import build, build_body, controller_of
from .registry import nearest
from .scenario.plan import Instance, instance_seed, load
from .signals import SENSOR_SLACK

#: the ids :func:`register_envs` registers
TRIAL_ID = "sfl/Trial-v0"
TICK_ID = "sfl/Tick-v0"

_SEEDS = 2**32  # a run's seed is an integer in [0, 2**32) (ScenarioModel.seed)
#: the dtype of every space (stable-baselines3 and most RL libraries expect float32)
DTYPE = np.float32


def _overrides(where: str, overrides: Any) -> list[str]:
    """``overrides`` as a list of ``KEY.PATH=VALUE`` strings (``sfl run --set``); TypeError otherwise."""
    if isinstance(overrides, str | bytes) or not isinstance(overrides, Sequence):
        raise TypeError(f"{where}: overrides: expected a list of 'KEY.PATH=VALUE' strings; got {overrides!r}")
    bad = [o for o in overrides if not isinstance(o, str)]
    if bad:
        raise TypeError(f"{where}: overrides: expected a list of 'KEY.PATH=VALUE' strings; got {bad[0]!r} in it")
    return list(overrides)


def _seed(where: str, seed: Any) -> int | None:
    """A run seed (an integer in [0, 2**32)) or None; ValueError naming ``where`` otherwise."""
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or not 0 <= seed < _SEEDS:
        raise ValueError(f"{where}: seed: expected None or an integer in [0, 2**32); got {seed!r}")
    return int(seed)


def _vector(where: str, value: Any, size: int, low: float | None = None, high: float | None = None) -> np.ndarray:
    """``value`` as a float64 vector of ``size`` finite numbers (within [low, high] when given); a ValueError that
    names ``where``, the shape or the first bad entry otherwise."""
    try:
        vector = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected {size} numbers; got {value!r}") from None
    if vector.shape != (size,):
        raise ValueError(f"{where}: expected shape ({size},); got shape {vector.shape}")
    bad = np.flatnonzero(~np.isfinite(vector))
    if bad.size:
        raise ValueError(f"{where}[{bad[0]}] = {vector[bad[0]]}: expected a finite number")
    if low is not None and high is not None:
        out = np.flatnonzero((vector < low) | (vector > high))
        if out.size:
            i = out[0]
            raise ValueError(
                f"{where}[{i}] = {vector[i]:g}: expected a number in [{low:g}, {high:g}] "
                f"(clip it: np.clip(action, {low:g}, {high:g}))"
            )
    return vector


def _flag(where: str, name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise TypeError(f"{where}: {name}: expected True or False; got {value!r}")
    return value


class _ScenarioEnv(gymnasium.Env):
    """What both doors share: the scenario's plan, its body worker and the run seed that numbers its trials."""

    metadata: ClassVar[dict] = {"render_modes": []}  # a run's pictures are its Rerun recording (sfl run)

    def __init__(
        self, scenario: str | Path, overrides: Sequence[str] = (), seed: int | None = None, normalize: bool = False
    ) -> None:
        where = type(self).__name__
        if not isinstance(scenario, str | Path):
            raise TypeError(f"{where}: scenario: expected the path of a scenario file; got {scenario!r}")
        #: the checked scenario (``sfl check``'s errors: file, key path, expected, given, did-you-mean)
        self.plan = load(scenario, _overrides(where, overrides), _seed(where, seed))
        #: actions in [-1, 1] and observations scaled to about [-1, 1] (see each door)
        self.normalize = _flag(where, "normalize", normalize)
        #: the body worker whose trials this environment runs (the first, when the scenario has several)
        self.body_instance: Instance = next(i for i in self.plan.instances if i.name == self.plan.bodies[0])
        self.run_seed = self.plan.scenario.seed
        self._next_trial = 0  # the trial id of the next episode
        self.trial_id = -1  # this episode's trial (-1: none yet)
        self._seeded: list[tuple[Any, Instance]] = []  # (module, instance) to reseed on reset(seed=...)
        self._closed = False

    def _open(self, call: str) -> None:
        """A RuntimeError naming ``call`` once the environment is closed (its physics is gone)."""
        if self._closed:
            raise RuntimeError(f"{type(self).__name__}.{call}: the environment is closed; make a new one")

    def _new_episode(self, seed: int | None) -> int:
        """Start episode k: trial k of the run seeded ``seed`` (or of the current run); return its trial seed."""
        self._open("reset")
        seed = _seed(f"{type(self).__name__}.reset", seed)
        super().reset(seed=seed)
        if seed is not None:
            self.run_seed = seed
            self._next_trial = 0
            for module, inst in self._seeded:  # as `sfl run --seed` builds them (Module.reset: the initial state)
                module.reset(instance_seed(self.run_seed, inst.spec_name))
        self.trial_id, self._next_trial = self._next_trial, self._next_trial + 1
        return trial_seed(self.run_seed, self.trial_id)

    def close(self) -> None:
        """Release the body's physics (a PyBullet client) and the controller; calling it again does nothing."""
        if not self._closed:
            self._closed = True
            for module, _ in self._seeded:
                module.close()
        super().close()


class TrialEnv(_ScenarioEnv):
    """One episode = one trial of the scenario's body and controller with the parameters the action names.

    - ``action``: a point of the scenario's parameter space (``space:``) in the unit cube, ``Box(0, 1, (dim,))``;
      axis i maps to ``low_i + u_i (high_i - low_i)`` on its target (``Axis.to_physical``). With ``normalize=True``
      the action is in [-1, 1] instead, the point u = (a + 1) / 2. A value outside the box, NaN or the wrong shape is
      a ValueError (the scenario's checks cover the space, not beyond it).
    - ``reward``: the trial's quality eta (the body's walking efficiency (5.7)-(5.8) for the walkers) when the body
      judges the trial a success, else ``failure_reward`` (0 by default: what a failure is worth to the OFC, which
      grades successes only).
    - ``observation``: ``[success, a_1, ..., a_dim]``, whether the trial just run succeeded (1) or not (0) and the
      action it tried, in the action's box; all zeros at ``reset`` (nothing tried yet). Every episode is one step,
      so the observation informs no decision; it says what happened, and is bounded (eta is not: a ratio of
      energies, it is the reward and in ``info``).
    - ``terminated`` is True after the one step; ``truncated`` is False. The environment declares
      ``metadata["autoreset_mode"] = SAME_STEP``: a vector of them should reset an env in the step that ended its
      trial (``gymnasium.make_vec`` does, through :func:`make_trial_vector`), so that every step runs a trial.
    - ``info``: ``trial_id``, ``trial_seed``; after the step also ``success``, ``eta``, ``metrics`` (the body's:
      distance, energy, fell, ...) and ``params`` (the physical parameters, ``{"controller": {...}, "body": {...}}``).
    """

    metadata: ClassVar[dict] = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        scenario: str | Path,
        overrides: Sequence[str] = (),
        seed: int | None = None,
        failure_reward: float = 0.0,
        render_mode: str | None = None,
        normalize: bool = False,
    ) -> None:
        if render_mode is not None:
            raise ValueError(f"TrialEnv: render_mode: expected None (no render modes); got {render_mode!r}")
        super().__init__(scenario, overrides, seed, normalize)
        if isinstance(failure_reward, bool) or not isinstance(failure_reward, int | float):
            raise TypeError(f"TrialEnv: failure_reward: expected a number; got {failure_reward!r}")
        if not math.isfinite(failure_reward):
            raise ValueError(f"TrialEnv: failure_reward: expected a finite number; got {failure_reward!r}")
        self.failure_reward = float(failure_reward)
        self.dim = self.plan.dim
        if self.dim == 0:
            raise ValueError(
                f"TrialEnv: {self.plan.file} has no parameter space (`space:` is empty); the action is a point of it"
            )
        self._low = -1.0 if self.normalize else 0.0
        self.action_space = spaces.Box(self._low, 1.0, (self.dim,), DTYPE)
        self.observation_space = spaces.Box(
            np.array([0.0] + [self._low] * self.dim, dtype=DTYPE), np.ones(self.dim + 1, dtype=DTYPE), dtype=DTYPE
        )
        self.body: Body = build_body(self.plan, self.body_instance)
        self._seeded = [(self.body, self.body_instance)]
        if self.body.link is not None:
            self._seeded.append((self.body.link.controller, controller_of(self.plan, self.body_instance)))
        self._trial_seed: int | None = None  # the trial this episode runs; None once it has run

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        if options:
            raise ValueError(f"TrialEnv.reset: options: expected none (the action sets the parameters); got {options}")
        self._trial_seed = self._new_episode(seed)
        return np.zeros(self.dim + 1, dtype=DTYPE), {"trial_id": self.trial_id, "trial_seed": self._trial_seed}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self._open("step")
        if self._trial_seed is None:
            raise RuntimeError("TrialEnv.step: no episode to step (one trial per episode): call reset() first")
        given = _vector("TrialEnv.step: action", action, self.dim, self._low, 1.0)
        unit = (given + 1.0) / 2.0 if self.normalize else given
        physical = self.plan.to_physical(unit)
        request = TrialRequest(  # as Conductor.trial_request builds it
            trial_id=self.trial_id,
            seed=self._trial_seed,
            body_params=physical["body"],
            controller_params=physical["controller"],
            log=False,
        )
        self._trial_seed = None
        result = self.body.handle(request)  # Body.trial: the lockstep loop with the controller in this process
        self.body.run_deferred()
        reward = float(result.quality) if result.success else self.failure_reward
        observation = np.concatenate(([float(result.success)], given)).astype(DTYPE)
        info = {
            "trial_id": request.trial_id,
            "trial_seed": request.seed,
            "success": bool(result.success),
            "eta": float(result.quality),
            "metrics": dict(result.metrics),
            "params": physical,
        }
        return observation, reward, True, False, info


def make_trial_vector(num_envs: int = 1, asynchronous: bool = False, **kwargs: Any) -> gymnasium.vector.VectorEnv:
    """``num_envs`` :class:`TrialEnv` (``kwargs`` as for one) as a vector env that resets an env in the step that ended
    its trial (``AutoresetMode.SAME_STEP``), so that every step runs a trial in every env: in this process
    (``SyncVectorEnv``) or each in a process of its own (``asynchronous=True``, ``AsyncVectorEnv``: one per core is
    what scales). ``gymnasium.make_vec("sfl/Trial-v0", num_envs=N, scenario=...)`` calls it. Env i of
    ``reset(seed=s)`` runs the trials of a run seeded s + i (Gymnasium's vector seeding)."""
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"make_trial_vector: num_envs: expected an integer >= 1; got {num_envs!r}")
    asynchronous = _flag("make_trial_vector", "asynchronous", asynchronous)

    def one() -> TrialEnv:
        return TrialEnv(**kwargs)

    vector = AsyncVectorEnv if asynchronous else SyncVectorEnv
    return vector([one] * num_envs, autoreset_mode=AutoresetMode.SAME_STEP)


class TickEnv(_ScenarioEnv):
    """One step = one control tick of the scenario's body; the agent is its controller (the scenario's is not used).

    - ``action``: the body's commands for one tick, in ``Body.COMMANDS`` order and units (the planar walker's four
      motor voltages, V; the humanoid's joint position targets, rad), ``Box(low, high)`` from each command's declared
      range. The body acts on a value beyond it as its own model says (a motor saturates, a target stops at its
      joint's limit); NaN, an infinity or the wrong shape is a ValueError. With ``normalize=True`` the action is in
      [-1, 1], mapped linearly onto each command's range (-1: low, 1: high).
    - ``observation``: the body's sensors after the tick, in ``Body.SENSORS`` order and units, ``Box`` from each
      sensor's declared range widened by ``SENSOR_SLACK`` (1 %) of it each side: the conformance check's tolerance
      (physics' joint stops and contacts are soft). A value beyond that is clipped to it: random 12-V commands drive
      the planar walker's knee up to 0.0014 rad past it into its soft stop. With ``normalize=True`` each sensor is
      scaled to 2 (x - low) / (high - low) - 1 of its declared range: [-1, 1] widened by 2 ``SENSOR_SLACK``.
      float32 either way; ``env.unwrapped.body.sense()`` gives the float64 values in their units.
    - ``reward``: forward progress over the tick, the change of the body's ``progress_metric`` (``distance``, m:
      what the walkers report in their trial metrics, read through ``Body.outcome()`` after every tick); on the tick
      that ends the trial, plus ``success_bonus`` if the body judges it a success (the thesis's success criterion:
      walked far enough without falling, or reached the finish line). ``progress_metric=None``: the bonus alone (a
      body that reports no ``distance`` needs it, or the name of a metric it reports).
    - ``terminated``: the body ended the trial before its ``duration`` (a fall, the finish line); ``truncated``: it
      ended at its ``duration`` (a time limit, not a state of the task; Gymnasium's "Handling Time Limits").
    - ``info``: ``trial_id``, ``trial_seed``, ``params`` (the body's physical parameters; the scenario's controller
      parameters for reference) at ``reset``; ``tick``, ``time`` (s of simulated time) at every step; and at the last
      step ``success``, ``eta`` and the body's ``metrics``.

    ``reset(options={"params": u})`` takes the trial's parameters from the point u of the scenario's parameter space
    (unit cube); by default its centre. Only the body's (``body.*`` axes and conditions) act here. The first
    observation of a trial depends on its seed only: the body starts every trial from its start state, whatever the
    last episode did.
    """

    def __init__(
        self,
        scenario: str | Path,
        overrides: Sequence[str] = (),
        seed: int | None = None,
        progress_metric: str | None = "distance",
        success_bonus: float = 1.0,
        render_mode: str | None = None,
        normalize: bool = False,
    ) -> None:
        if render_mode is not None:
            raise ValueError(f"TickEnv: render_mode: expected None (no render modes); got {render_mode!r}")
        super().__init__(scenario, overrides, seed, normalize)
        if progress_metric is not None and not isinstance(progress_metric, str):
            raise TypeError(f"TickEnv: progress_metric: expected a metric's name or None; got {progress_metric!r}")
        if isinstance(success_bonus, bool) or not isinstance(success_bonus, int | float):
            raise TypeError(f"TickEnv: success_bonus: expected a number; got {success_bonus!r}")
        if not math.isfinite(success_bonus):
            raise ValueError(f"TickEnv: success_bonus: expected a finite number; got {success_bonus!r}")
        self.progress_metric = progress_metric
        self.success_bonus = float(success_bonus)
        body_cls = self.body_instance.cls
        if not body_cls.COMMANDS:
            raise ValueError(
                f"TickEnv: body `{self.body_instance.spec_name}` ({body_cls.__name__}) takes no commands, so there is "
                f"no tick to act on; use {TRIAL_ID} for its trials"
            )
        #: the signals of the observation and of the action, in their order (name, unit, range, meaning)
        self.sensors, self.commands = body_cls.SENSORS, body_cls.COMMANDS
        low = np.array([s.low for s in self.sensors])
        high = np.array([s.high for s in self.sensors])
        slack = SENSOR_SLACK * (high - low)
        self._sensor_low, self._sensor_high = low - slack, high + slack  # float64: the clip, in the body's units
        # normalised observation: (x - centre) * scale, x in [low, high] -> [-1, 1]
        self._sensor_centre, self._sensor_scale = (low + high) / 2.0, 2.0 / (high - low)
        command_low = np.array([c.low for c in self.commands])
        command_high = np.array([c.high for c in self.commands])
        # normalised action: centre + a * half, a in [-1, 1] -> [low, high]
        self._command_centre, self._command_half = (command_low + command_high) / 2.0, (command_high - command_low) / 2
        if self.normalize:
            bound = 1.0 + 2.0 * SENSOR_SLACK
            self.observation_space = spaces.Box(-bound, bound, (len(self.sensors),), DTYPE)
            self.action_space = spaces.Box(-1.0, 1.0, (len(self.commands),), DTYPE)
        else:
            # float32 bounds: rounding is monotonic, so a value clipped in float64 and rounded stays within them
            self.observation_space = spaces.Box(self._sensor_low.astype(DTYPE), self._sensor_high.astype(DTYPE))
            self.action_space = spaces.Box(command_low.astype(DTYPE), command_high.astype(DTYPE))
        self._shape = (len(self.commands),)
        self._observation = np.empty(len(self.sensors))  # the clipped sensor values, reused every tick
        self.body: Body = build(self.body_instance)
        self.body.worker = self.body_instance.name
        self._seeded = [(self.body, self.body_instance)]
        self.tick = 0
        self._running = False
        self._progress = 0.0

    def _read_progress(self) -> float:
        if self.progress_metric is None:
            return 0.0
        metrics = self.body.outcome()[2]
        value = metrics.get(self.progress_metric)
        if isinstance(value, bool) or not isinstance(value, int | float):
            numbers = [k for k, v in metrics.items() if isinstance(v, int | float) and not isinstance(v, bool)]
            hint = nearest(self.progress_metric, numbers)
            raise ValueError(
                f"TickEnv: progress_metric: {type(self.body).__name__} reports no number {self.progress_metric!r}"
                + (f" (did you mean `{hint}`?)" if hint else "")
                + f"; its metrics are {numbers}; pass progress_metric= one of them, or None for the success bonus "
                "alone (docs/gymnasium.md)"
            )
        return float(value)

    def _sense(self) -> np.ndarray:
        """The observation: the body's sensors, checked finite, clipped to the box (scaled when normalising)."""
        values = self.body.sense()
        if not _finite_vector(values):
            self.body._check_sensors(np.asarray(values, dtype=np.float64), self.trial_id, self.tick)  # names it
        clipped = self._observation
        np.maximum(values, self._sensor_low, out=clipped)
        np.minimum(clipped, self._sensor_high, out=clipped)
        if self.normalize:
            clipped -= self._sensor_centre
            clipped *= self._sensor_scale
        return clipped.astype(DTYPE)

    def _command(self, action: Any) -> np.ndarray:
        """The action as the body's float64 commands; a ValueError naming the entry or the shape otherwise."""
        if type(action) is np.ndarray and action.shape == self._shape and action.dtype.kind == "f":
            command = action.astype(np.float64)  # a copy: the caller's array stays theirs
            if not _finite_vector(command):
                _vector("TickEnv.step: action", command, len(command))  # raises, naming the entry
        else:
            command = _vector("TickEnv.step: action", action, len(self.commands))
        if self.normalize:
            command *= self._command_half
            command += self._command_centre
        return command

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        self._open("reset")
        options = dict(options or {})
        unit = options.pop("params", None)
        if options:
            raise ValueError(f"TickEnv.reset: options: expected only 'params'; got {sorted(options)}")
        unit = (
            np.full(self.plan.dim, 0.5)
            if unit is None
            else _vector("TickEnv.reset: options['params']", unit, self.plan.dim, 0.0, 1.0)
        )
        seed_of_trial = self._new_episode(seed)
        physical = self.plan.to_physical(unit)
        request = TrialRequest(
            trial_id=self.trial_id,
            seed=seed_of_trial,
            body_params=physical["body"],
            controller_params=physical["controller"],
            log=False,
        )
        self.body.logging = False
        self.body.start_trial(request)
        self.tick, self._running = 0, True
        self._progress = self._read_progress()
        info = {"trial_id": self.trial_id, "trial_seed": seed_of_trial, "params": copy.deepcopy(physical)}
        return self._sense(), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        self._open("step")
        if not self._running:
            raise RuntimeError("TickEnv.step: the trial is over (or not started): call reset() first")
        body = self.body
        body.actuate(self._command(action))
        self.tick += 1
        dt = body.params.control_dt
        progress = self._read_progress()
        reward, self._progress = progress - self._progress, progress
        info: dict[str, Any] = {"tick": self.tick, "time": self.tick * dt}
        terminated = truncated = False
        if body.done:
            self._running = False
            success, eta, metrics = body.outcome()
            reward += self.success_bonus if success else 0.0
            info |= {"success": bool(success), "eta": float(eta), "metrics": dict(metrics)}
            # the body's time limit is `t >= duration` (every walker's `done`); half a tick absorbs float sums
            truncated = self.tick * dt >= body.params.duration - dt / 2
            terminated = not truncated
        return self._sense(), float(reward), terminated, truncated, info


def register_envs() -> None:
    """Register ``sfl/Trial-v0`` (with its vector entry point) and ``sfl/Tick-v0`` with Gymnasium; run on import,
    again it does nothing."""
    if TRIAL_ID not in gymnasium.registry:
        gymnasium.register(
            id=TRIAL_ID, entry_point=f"{__name__}:TrialEnv", vector_entry_point=f"{__name__}:make_trial_vector"
        )
    if TICK_ID not in gymnasium.registry:
        gymnasium.register(id=TICK_ID, entry_point=f"{__name__}:TickEnv")


register_envs()
