"""How a run ends, and the exit code each ending gives.

A run ends ``completed`` only when its protocol spent its whole budget (every planned trial,
every grid point). Anything else says why in ``stop_reason``:

========== ============================================================== =========
status     when                                                           exit code
========== ============================================================== =========
completed  the protocol's budget was met                                  0
failed     a module failed (an error reply, a death it cannot recover     1
           from, a non-finite value) or the run could not go on
stalled    the protocol stopped early on its own: the decision cap,       3
           too many decisions without a trial
interrupted Ctrl-C or SIGTERM                                             130
========== ============================================================== =========

Two more exit codes come before a run exists: 2 for bad input (a scenario, an argument, an
``--out`` that already holds a run) and 4 for the environment (a port in use, an ``--out``
that cannot be written, a full disk, no display for ``--viewer``).
"""

from __future__ import annotations

from enum import StrEnum


class RunStatus(StrEnum):
    COMPLETED = "completed"
    FAILED = "failed"
    STALLED = "stalled"
    INTERRUPTED = "interrupted"


EXIT_COMPLETED = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_STALLED = 3
EXIT_ENVIRONMENT = 4
EXIT_INTERRUPTED = 130

EXIT_CODES: dict[RunStatus, int] = {
    RunStatus.COMPLETED: EXIT_COMPLETED,
    RunStatus.FAILED: EXIT_FAILED,
    RunStatus.STALLED: EXIT_STALLED,
    RunStatus.INTERRUPTED: EXIT_INTERRUPTED,
}


class EnvironmentProblem(RuntimeError):
    """The machine will not let the run start or keep its records (port in use, unwritable or full
    folder, no display): one line for the user, exit code 4."""


class BadInput(ValueError):
    """A command-line value the user must change (exit code 2)."""
