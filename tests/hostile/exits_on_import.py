"""A user module that calls sys.exit() on import (for tests/hostile/impl_exits.yaml)."""

import sys

sys.exit(3)
