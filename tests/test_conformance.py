import pytest

from sfl_brain.conformance import check_module
from sfl_brain.registry import registered, resolve


@pytest.mark.parametrize("name", sorted(registered()))
def test_every_registered_module_conforms(name):
    cls, _ = resolve(name)
    check_module(cls)
