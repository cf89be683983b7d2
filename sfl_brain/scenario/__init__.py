"""A scenario: the file that says which modules run, with what parameters, under which protocol.

Here it is read safely (:mod:`.loading`, a bounded YAML loader), checked against its schema (:mod:`.schema`) before
any process starts (an error names the file, the key path, what was expected and what was given) and built into a
:class:`Plan`. This package imports only the contract (module, body, signals, registry, messages) and the
proposers; everything that runs a plan imports it.
"""

from .errors import Problem, ScenarioError, problems_from
from .loading import MAX_BYTES, apply_overrides, parse_yaml, read_yaml
from .plan import Instance, Plan, build_plan, instance_seed, load
from .schema import ConditionsProtocol, PatternSpaceAnalysis, ScenarioModel

__all__ = [
    "MAX_BYTES",
    "ConditionsProtocol",
    "Instance",
    "PatternSpaceAnalysis",
    "Plan",
    "Problem",
    "ScenarioError",
    "ScenarioModel",
    "apply_overrides",
    "build_plan",
    "instance_seed",
    "load",
    "parse_yaml",
    "problems_from",
    "read_yaml",
]
