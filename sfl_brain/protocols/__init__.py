"""The protocols: what a run does with its modules (learn, sweep, exploit, conditions), trial by trial.

One file per protocol (:mod:`.learn`, :mod:`.sweep`, :mod:`.exploit`, :mod:`.conditions`), each a function of a
:class:`~.conductor.Conductor`. A protocol asks a :class:`~.service.ModuleService` for trials and records each row;
it never sees a process or Zenoh, so the same code runs with every module in one process (:mod:`.local`) and with one
process per module (:mod:`sfl_brain.runtime`). This package imports the contract, the scenario, the proposers and
recording; never the runtime.
"""

from .conditions import condition_cases, repeat_seed, run_conditions
from .conductor import Conductor, trial_seed
from .exploit import run_exploit
from .learn import run_learn, trial_progress
from .sweep import run_sweep

#: each protocol kind of a scenario (``protocol.kind``) and the function that runs it with a :class:`Conductor`
PROTOCOLS = {"learn": run_learn, "sweep": run_sweep, "exploit": run_exploit, "conditions": run_conditions}

__all__ = ["PROTOCOLS", "Conductor", "condition_cases", "repeat_seed", "trial_progress", "trial_seed"]
