"""The protocols: what a run does with its modules (learn, sweep, exploit, conditions), trial by trial.

A protocol asks a :class:`~sfl_brain.protocols.service.ModuleService` for trials and records each row; it never
sees a process or Zenoh, so the same code runs with every module in one process (:mod:`.local`) and with one
process per module (:mod:`sfl_brain.runtime`). This package imports the contract, the scenario, the proposers and
recording; never the runtime.
"""

from .conductor import PROTOCOLS, Conductor, condition_cases, repeat_seed, trial_progress, trial_seed

__all__ = ["PROTOCOLS", "Conductor", "condition_cases", "repeat_seed", "trial_progress", "trial_seed"]
