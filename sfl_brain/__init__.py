"""sfl-brain: success-failure learning (J. Nassour's thesis) as processes over Zenoh, recorded in Rerun.

The runtime lives here; the brain modules and bodies install as :mod:`sfl_brain.modules` and
:mod:`sfl_brain.bodies` (the folders ``modules/`` and ``bodies/`` of a checkout).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("sfl-brain")
except PackageNotFoundError:  # a checkout that was never installed
    __version__ = "0+unknown"

from ._moved import install as _install_moved

_install_moved()  # the flat paths of before issue 30 (``sfl_brain.records``, ...) still import
