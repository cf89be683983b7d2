"""Hostile and careless scenario files: each one fails fast with its pinned error and exit code 2.

Every ``*.yaml`` here is a bad scenario (``python tests/hostile/make_files.py`` rewrites them);
``CASES`` pins the text each must produce. They run through ``load()`` in-process, through the
real ``sfl check`` command in-process (click's CliRunner), and a few through a real subprocess.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from sfl_brain.cli import main
from sfl_brain.scenario import MAX_BYTES, ScenarioError, load

from ..conftest import SCENARIOS, sfl

HERE = Path(__file__).parent
EXPECTED_TYPE = "expected an integer; got"
TERRAIN = "expected a terrain profile: pieces `length:slope_deg` separated by commas, e.g. '0.5:0,1.0:6,1.0:-4'"
TAG = "is not allowed; expected plain values, lists and mappings"

#: file -> the texts its error must contain (after ``FILE: ``)
CASES: dict[str, list[str]] = {
    # --- YAML bombs and limits
    "alias_bomb.yaml": [
        "bomb.d: line 17, column 6: expands to more than 5000 values (aliases count their anchor's again)"
    ],
    "alias_recursive.yaml": ["loop.1: line 12, column 7: an alias refers to its own anchor (a recursive structure)"],
    "alias_deep_chain.yaml": ["chain.c29.0: line 41, column 8: nested more than 32 deep (after expanding aliases)"],
    "deep_nesting_lists.yaml": ["line 12, column 46: nested more than 32 deep"],
    "deep_nesting_mappings.yaml": ["line 12, column 129: nested more than 32 deep"],
    "deep_nesting_block.yaml": ["line 43, column 63: nested more than 32 deep"],
    "many_values.yaml": ["line 12, column 14838: more than 5000 values"],
    "huge_int.yaml": ["seed: line 2, column 7: an integer of 5000 digits; expected at most 100"],
    "huge_float.yaml": ["space.0.low: expected a finite number; got .inf"],
    # --- encodings and bytes
    "non_utf8.yaml": ["line 3, column 17 (byte 38): expected UTF-8 text; got byte 0xe9 (invalid continuation byte)"],
    "utf16.yaml": ["line 1, column 1 (byte 0): expected UTF-8 text; got byte 0xff (invalid start byte)"],
    "binary_garbage.yaml": ["line 1, column 3 (byte 2): expected UTF-8 text; got byte 0xbb (invalid start byte)"],
    "nul_byte.yaml": ["line 1, column 11: not valid YAML: character U+0000 is not allowed"],
    "control_chars.yaml": ["line 3, column 14: not valid YAML: character U+001B is not allowed"],
    # --- YAML structure
    "empty.yaml": ["the file is empty; expected a mapping with name, protocol, space, modules"],
    "comments_only.yaml": ["the file is empty; expected a mapping with name, protocol, space, modules"],
    "top_list.yaml": ["expected a mapping with name, protocol, space, modules at the top; got a list"],
    "top_scalar.yaml": ["at the top; got the single value 'hello'"],
    "two_documents.yaml": ["line 12, column 1: not valid YAML: but found another document"],
    "yaml_syntax.yaml": ["line 13, column 1: not valid YAML: expected ',' or ']', but got '<stream end>'"],
    "tab_indent.yaml": ["line 8, column 1: not valid YAML: found character '\\t' that cannot start any token"],
    "duplicate_top.yaml": ["seed: line 7, column 1: duplicate key (first at line 2, column 1); expected each key once"],
    "duplicate_nested.yaml": ["protocol.trials: line 3, column 36: duplicate key (first at line 3, column 25)"],
    "duplicate_module.yaml": ["modules.acc: line 12, column 3: duplicate key (first at line 8, column 3)"],
    "duplicate_in_list_item.yaml": ["space.0.low: line 5, column 48: duplicate key (first at line 5, column 31)"],
    "bool_key.yaml": ["line 12, column 1: key 'on' is read as bool; expected a text key (quote it: 'on')"],
    "int_key.yaml": ["modules: line 12, column 3: key '1' is read as int; expected a text key (quote it: '1')"],
    "python_tag.yaml": [f"name: line 1, column 7: tag `!!python/object/apply:os.system` {TAG}"],
    "python_name_tag.yaml": [f"seed: line 2, column 7: tag `!!python/name:os.getpid` {TAG}"],
    "custom_tag.yaml": [f"seed: line 2, column 7: tag `!env` {TAG}"],
    "set_tag.yaml": [f"extra: line 12, column 8: tag `!!set` {TAG}"],
    "binary_tag.yaml": [f"description: line 3, column 14: tag `!!binary` {TAG}"],
    "bad_explicit_int.yaml": ["line 2, column 7: not valid YAML: cannot read 'abc': ValueError: invalid literal"],
    "merge_not_mapping.yaml": ["line 3, column 16: not valid YAML: expected a mapping or list of mappings for merging"],
    # --- strict types
    "trials_string.yaml": [f"protocol.trials: {EXPECTED_TYPE} '40' (did you mean `40`?)"],
    "trials_bool.yaml": [f"protocol.trials: {EXPECTED_TYPE} true"],
    "trials_float.yaml": [f"protocol.trials: {EXPECTED_TYPE} 40.0"],
    "seed_string.yaml": [f"seed: {EXPECTED_TYPE} '7' (did you mean `7`?)"],
    "seed_float.yaml": [f"seed: {EXPECTED_TYPE} 7.5"],
    "low_string.yaml": ["space.0.low: expected a number; got '0' (did you mean `0`?)"],
    "high_yes.yaml": ["space.0.high: expected a number; got true"],
    "shape_strings.yaml": [f"modules.acc.params.shape.0: {EXPECTED_TYPE} '10' (did you mean `10`?)"],
    "param_bool_for_number.yaml": ["modules.vigilance.params.value: expected a number; got false"],
    "modules_list.yaml": ["modules: expected a mapping; got ['acc', 'vigilance', 'ofc', 'body']"],
    "params_null.yaml": ["modules.acc.params: expected a mapping; got null"],
    # --- finite numbers
    "low_inf.yaml": ["space.0.low: expected a finite number; got -.inf"],
    "high_nan.yaml": ["space.0.high: expected a finite number; got .nan"],
    "condition_inf.yaml": ["conditions.body.z: expected a finite number; got .inf"],
    "param_nan.yaml": ["modules.vigilance.params.value: expected a finite number; got .nan"],
    "timeout_inf.yaml": ["timeouts.ready: expected a finite number; got .inf"],
    "lease_too_short.yaml": ["timeouts.lease: input should be greater than or equal to 0.5; got 0.1"],
    "timeout_misspelt.yaml": [
        "timeouts.hang: unknown key; expected one of ['lease', 'ready', 'request', 'tick', 'trial']"
    ],
    # --- what would fail at start
    "map_shape_huge.yaml": [
        "modules.acc.params: expected at most 4096 neurons (e.g. 64 x 64 or 16 x 16 x 16); shape "
        "[1000, 1000, 1000] has 1000000000, and its success and failure maps would need about 72 EB of memory"
    ],
    "map_shape_just_too_big.yaml": [
        "shape [65, 64] has 4160, and its success and failure maps would need about 969 MB"
    ],
    "terrain_unknown.yaml": [f"conditions.body.terrain: {TERRAIN}; got 'hilly' (terrains have no names)"],
    "terrain_malformed.yaml": [f"conditions.body.terrain: {TERRAIN}; piece 1 of '0.5:0,1.0:' is '1.0:'"],
    "terrain_steep.yaml": [
        "conditions.body.terrain: piece 1 of terrain '0.5:0,1.0:80': expected a slope within +-45 deg; got 80.0"
    ],
    "terrain_number.yaml": [f"conditions.body.terrain: {TERRAIN}; got 3 (for a constant slope use body.slope_deg)"],
    "terrain_axis.yaml": [f"space.0.target: {TERRAIN}; got 0.0"],
    "slope_text.yaml": ["conditions.body.slope_deg: expected a number of degrees; got 'steep'"],
    "impl_raises.yaml": [
        "modules.vigilance.impl: importing ",
        "raises_on_import.py failed: RuntimeError: boom on import",
    ],
    "impl_exits.yaml": ["modules.vigilance.impl: importing ", "exits_on_import.py failed: SystemExit: 3"],
    "impl_base_exception.yaml": ["base_exception_on_import.py failed: Doom: not an Exception"],
    "impl_hangs.yaml": ["hangs_on_import.py did not finish within 0.5 s (timeouts.ready)"],
    "impl_missing_file.yaml": ["modules.vigilance.impl: file nowhere.py not found (looked in "],
    "impl_missing_module.yaml": [
        "modules.vigilance.impl: importing no_such_package.vig failed: ModuleNotFoundError: No module named"
    ],
    "impl_not_a_module.yaml": ["modules.vigilance.impl: json:JSONDecoder is not a sfl_brain Module subclass"],
    "impl_unregistered.yaml": [
        "modules.vigilance.impl: no registered implementation 'vigilence' (did you mean `vigilance`?)"
    ],
    "restart_brain.yaml": [
        "modules.acc.restart: expected 'never' for ACC: only bodies and controllers are restarted "
        "(a brain module holds learnt state that a restart would lose); got 'on-failure'"
    ],
    "restart_typo.yaml": [
        "modules.body.restart: expected one of 'never' or 'on-failure'; got 'on-failur' (did you mean `on-failure`?)"
    ],
    # --- unknown keys and names
    "unknown_key.yaml": ["protocl: unknown key; expected one of ['conditions', ", "(did you mean `protocol`?)"],
    "unknown_nested_key.yaml": [
        "space.0.hihg: unknown key; expected one of ['high', 'low', 'name', 'steps', 'target', 'unit'] "
        "(did you mean `high`?)"
    ],
    "unknown_param.yaml": ["modules.vigilance.params.stepp: unknown key; expected one of [", "(did you mean `step`?)"],
    "enum_typo.yaml": [
        "lockstep.pin_cpus: expected one of 'never', 'auto' or 'always'; got 'alwys' (did you mean `always`?)"
    ],
    "protocol_typo.yaml": [
        "protocol.kind: expected one of 'learn', 'sweep', 'exploit', 'conditions'; got 'lern' (did you mean `learn`?)"
    ],
}

#: ``--set`` overrides on a valid scenario -> the texts the error must contain
OVERRIDES: list[tuple[str, str]] = [
    ("space.99.low=1", "--set space.99.low: space is a list of 2; expected an index 0..1; got '99'"),
    ("space.x.low=1", "--set space.x.low: space is a list of 2; expected an index 0..1; got 'x'"),
    ("=3", "--set: expected KEY.PATH=VALUE; got '=3'"),
    ("a.b.c", "--set: expected KEY.PATH=VALUE; got 'a.b.c'"),
    ("seed.x=3", "--set seed.x: seed is 1, not a mapping or list; cannot set 'x' in it"),
    ("a..b=1", "--set a..b: expected KEY.PATH of dot-separated keys; got 'a..b'"),
    ("seed=.inf", "seed: expected a finite number; got .inf"),
    ("space.0.high=.nan", "space.0.high: expected a finite number; got .nan"),
    ("seed=[1", "--set seed: line 1, column 3: not valid YAML: expected ',' or ']'"),
    ("protocol.trials='40'", "protocol.trials: expected an integer; got '40' (did you mean `40`?)"),
    ("description=" + "[" * 40, "--set description: line 1, column 33: nested more than 32 deep"),
    ("modules.acc.restart=on-failure", "modules.acc.restart: expected 'never' for ACC"),
    ("modules.acc.params.shape=[100, 100]", "shape [100, 100] has 10000, and its success and failure maps"),
]


def hostile_files() -> list[str]:
    return sorted(p.name for p in HERE.glob("*.yaml"))


def expect_error(path, overrides=()) -> str:
    start = time.perf_counter()
    with pytest.raises(ScenarioError) as info:
        load(path, list(overrides))
    assert time.perf_counter() - start < 2.0, f"{path} took {time.perf_counter() - start:.1f} s"
    return str(info.value)


def test_every_hostile_file_has_a_pinned_error_and_there_are_at_least_40():
    assert hostile_files() == sorted(CASES)
    assert len(CASES) >= 40


@pytest.mark.parametrize("name", sorted(CASES))
def test_load_fails_fast_with_the_pinned_error(name):
    path = HERE / name
    text = expect_error(path)
    assert text.startswith(f"{path}: "), text
    for expected in CASES[name]:
        assert expected in text


@pytest.mark.parametrize("name", sorted(CASES))
def test_sfl_check_exits_2_with_the_error_and_no_traceback(name):
    result = CliRunner().invoke(main, ["check", str(HERE / name)])
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit)
    assert "Traceback" not in result.output and "sfl: invalid scenario" in result.output
    for expected in CASES[name]:
        assert expected in result.output


def test_a_10_mb_file_is_refused_by_its_size_before_parsing(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text("name: big\n" + "# padding\n" * 1_048_576)
    size = path.stat().st_size
    assert size > 10_000_000
    assert f"expected a scenario of at most {MAX_BYTES // 1024} KiB; the file has {size} bytes" in expect_error(path)
    result = CliRunner().invoke(main, ["check", str(path)])
    assert result.exit_code == 2 and "Traceback" not in result.output


def test_a_file_without_an_end_is_read_only_up_to_the_limit():
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero")
    text = expect_error("/dev/zero")
    assert f"the file has more than {MAX_BYTES} bytes" in text


@pytest.mark.parametrize("path, expected", [("missing.yaml", "No such file or directory"), (".", "Is a directory")])
def test_unreadable_paths_are_errors(path, expected):
    text = expect_error(HERE / path)
    assert "cannot read: " + expected in text


@pytest.mark.parametrize("override, expected", OVERRIDES)
def test_bad_overrides_are_clear_errors(override, expected):
    scenario = SCENARIOS / "analytic_learn.yaml"
    assert expected in expect_error(scenario, [override])
    result = CliRunner().invoke(main, ["check", str(scenario), "--set", override])
    assert result.exit_code == 2 and "Traceback" not in result.output and expected in result.output


def test_an_import_that_failed_is_tried_again_and_a_good_one_is_cached(tmp_path):
    """A failed import is forgotten (a fixed file is read again), not left half-done in sys.modules."""
    scenario = tmp_path / "s.yaml"
    scenario.write_text((HERE / "impl_raises.yaml").read_text().replace("raises_on_import.py", "mine.py"))
    (tmp_path / "mine.py").write_text("raise ValueError('not yet')\n")
    assert "mine.py failed: ValueError: not yet" in expect_error(scenario)
    (tmp_path / "mine.py").write_text("from modules.vigilance import Vigilance\n")
    assert load(scenario).scenario.name == "hostile"


@pytest.mark.parametrize(
    "name",
    ["alias_bomb.yaml", "non_utf8.yaml", "deep_nesting_lists.yaml", "impl_exits.yaml", "impl_hangs.yaml"],
)
def test_real_sfl_check_exits_2_without_traceback(name):
    done = sfl("check", str(HERE / name), timeout=60)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert CASES[name][-1] in done.stderr


def test_real_sfl_check_refuses_a_10_mb_file(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_bytes(b"name: big\n" + b"x" * 10_485_760)
    done = sfl("check", str(path), timeout=60)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert f"the file has {10_485_770} bytes" in done.stderr
