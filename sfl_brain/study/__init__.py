"""A study: many ``sfl run`` of one scenario over varied settings and seeds, on this machine (:mod:`.study`) or on a
Dask cluster (:mod:`.cluster`), watched in the terminal (:mod:`.view`). It runs plans through the runtime and
reads their records; reports read it, never the other way round.
"""

from .._moved import forward

__getattr__ = forward(__name__, __name__ + ".study")  # ``sfl_brain.study.X`` of before issue 30 is ``.study.X``
