"""The machinery that runs a plan: one process per module (:mod:`.processes`), each hosted by :mod:`.host` and
talking over Zenoh (:mod:`.bus`), a body and its controller in lockstep over a tick link (:mod:`.ticklink`), the
:class:`~.supervisor.Supervisor` that starts, watches and restarts them, and :func:`.run.run` that ties a run
together. It may import everything below it (contract, scenario, recording, protocols), never a study or a report.
"""

from .._moved import forward

__getattr__ = forward(
    __name__, __name__ + ".supervisor"
)  # ``sfl_brain.runtime.X`` of before issue 30 is ``.supervisor.X``
