"""A scenario: the file that says which modules run, with what parameters, under which protocol.

Here it is read safely (:mod:`.plan`'s bounded YAML loader), checked against its schema before any process
starts (an error names the file, the key path, what was expected and what was given) and built into a
:class:`Plan`. This package imports only the contract (module, body, signals, registry, messages) and the
proposers; everything that runs a plan imports it.
"""

from .plan import (
    MAX_BYTES,
    ConditionsProtocol,
    Instance,
    PatternSpaceAnalysis,
    Plan,
    Problem,
    ScenarioError,
    ScenarioModel,
    apply_overrides,
    build_plan,
    instance_seed,
    load,
    parse_yaml,
    problems_from,
    read_yaml,
)

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
