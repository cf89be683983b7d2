"""Property-based tests of the scenario loader: whatever goes in, out comes a Plan or a ScenarioError.

Never a traceback of another kind: arbitrary bytes, YAML-ish text made of the characters and words
that matter to YAML, valid scenarios with values swapped, deleted or added anywhere, and arbitrary
``--set`` overrides.
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sfl_brain.scenario import Plan, ScenarioError, load

SETTINGS = settings(
    max_examples=200,
    deadline=None,
    database=None,  # nothing written into the working tree
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)

VALID = {
    "name": "prop",
    "seed": 1,
    "protocol": {"kind": "learn", "trials": 5, "batch": 8},
    "space": [
        {"name": "x", "target": "body.x", "low": 0, "high": 1.0},
        {"name": "y", "target": "body.y", "low": 0.0, "high": 1, "steps": 3},
    ],
    "conditions": {"body.z": 0.5},
    "modules": {
        "acc": {"impl": "acc", "params": {"shape": [4, 4]}},
        "vigilance": {"impl": "vigilance", "params": {"mode": "fixed", "value": -0.1}},
        "ofc": {"impl": "ofc"},
        "body": {"impl": "analytic", "workers": 1, "restart": "on-failure"},
    },
    "timeouts": {"ready": 60, "tick": 10},
    "lockstep": {"spin_us": 200, "pin_cpus": "never"},
}

#: words and characters that mean something to YAML or to a scenario
TOKENS = [
    ":", ": ", " ", "  ", "\n", "- ", "[", "]", "{", "}", ",", "&a ", "*a", "&b ", "*b", "<<: ", "!!python/object ",
    "!!str ", "!!int ", "!!set ", "!x ", "'", '"', "#", "? ", "|\n", ">\n", "---\n", "...\n", "%YAML 1.1\n", "\t",
    "\x00", "\x85", "\ufeff", "é", "\\", "name", "seed", "protocol", "kind", "learn", "sweep", "trials", "space",
    "modules", "impl", "acc", "body", "analytic", "params", "shape", "restart", "on-failure", "low", "high", "1",
    "-1", "0.5", "1e3", "1.0e+999", ".inf", "-.inf", ".nan", "true", "no", "~", "null", "2024-01-01", "0x1f", "0o17",
    "9" * 120,
]  # fmt: skip

LEAF = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats()
    | st.text(max_size=12)
    | st.sampled_from(["acc", "analytic", "on-failure", "learn", "sweep", "body.x", "x.py:X", "1", [3, 3]])
)
VALUES = st.recursive(
    LEAF,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=8,
)


def paths(value, prefix=()) -> list[tuple]:
    """Every key path inside a nested dict/list."""
    out = [prefix]
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        out += paths(item, (*prefix, key))
    return out


@st.composite
def mutated(draw) -> dict:
    """The valid scenario with a few values replaced, deleted or added at any depth."""
    raw = copy.deepcopy(VALID)
    for _ in range(draw(st.integers(1, 4))):
        path = draw(st.sampled_from(paths(raw)))
        if not path:
            continue
        parent = raw
        for key in path[:-1]:
            parent = parent[key]
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        if action == "replace":
            parent[path[-1]] = copy.deepcopy(draw(VALUES))
        elif action == "delete":
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[draw(st.text(max_size=8))] = copy.deepcopy(draw(VALUES))
    return raw


def outcome(data: bytes, overrides=()) -> Plan | ScenarioError:
    """Load ``data`` as a scenario file: a Plan or a ScenarioError, and nothing else."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "scenario.yaml"
        path.write_bytes(data)
        try:
            plan = load(path, list(overrides))
        except ScenarioError as exc:
            assert str(exc).startswith(str(path))
            return exc
    assert isinstance(plan, Plan)
    return plan


def test_the_valid_scenario_is_valid():
    assert isinstance(outcome(yaml.safe_dump(VALID).encode()), Plan)


@SETTINGS
@given(st.binary(max_size=2048))
def test_arbitrary_bytes_give_a_plan_or_a_scenario_error(data):
    outcome(data)


@SETTINGS
@given(st.lists(st.sampled_from(TOKENS), max_size=80).map("".join))
def test_yaml_ish_text_gives_a_plan_or_a_scenario_error(text):
    outcome(text.encode("utf-8", errors="surrogatepass"))


@SETTINGS
@given(mutated())
def test_mutated_scenarios_give_a_plan_or_a_scenario_error(raw):
    outcome(yaml.safe_dump(raw, allow_unicode=True).encode("utf-8", errors="surrogatepass"))


@SETTINGS
@given(st.lists(st.text(max_size=30) | st.sampled_from(["seed=", "space.0.low=", "modules.acc.params.shape="]).flatmap(
    lambda key: st.just(key) if not key.endswith("=") else st.sampled_from(TOKENS).map(lambda v: key + v)
), max_size=3))  # fmt: skip
def test_arbitrary_overrides_give_a_plan_or_a_scenario_error(overrides):
    outcome(yaml.safe_dump(VALID).encode(), overrides)
