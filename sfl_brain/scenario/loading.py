"""Reading a scenario file safely (see ``docs/reliability.md``): at most :data:`MAX_BYTES`, strict UTF-8, a safe YAML
loader with limits on nesting and values (also after expanding aliases), no duplicate keys, no tags beyond plain
values, lists and mappings; and ``--set KEY.PATH=VALUE`` overrides, parsed with the same limits."""

from __future__ import annotations

import copy
import math
import os
from pathlib import Path
from typing import Any

import yaml
from yaml.constructor import ConstructorError
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

from .errors import (
    Problem,
    ScenarioError,
    _short,
)

# --------------------------------------------------------------------------------------------
# Reading a file: size, encoding, a safe YAML loader with limits
# --------------------------------------------------------------------------------------------

#: a scenario file is read only up to this many bytes (the shipped ones are under 2 kB; pure-Python
#: YAML scans about 1 MB of text a second, so this bounds a hostile file to well under a second)
MAX_BYTES = 256 * 1024
#: nesting of mappings and lists, also after expanding aliases (the shipped scenarios nest 5 deep)
MAX_DEPTH = 32
#: YAML values (nodes) in a file, also after expanding aliases: each alias counts its anchor's again
#: (the shipped scenarios have under 100; PyYAML composes about 10 000 a second on a busy machine)
MAX_NODES = 5_000
#: digits of an integer (Python refuses to read more than 4300)
MAX_DIGITS = 100

_TAG = "tag:yaml.org,2002:"
_MERGE = _TAG + "merge"
_SCALAR_TAGS = {_TAG + t for t in ("str", "int", "float", "bool", "null")}
_KINDS = {ScalarNode: "a plain value", SequenceNode: "a list", MappingNode: "a mapping"}


class _YAMLLimit(yaml.MarkedYAMLError):
    """A limit of :class:`SafeLoader` was hit; ``path`` is the key path where it was."""

    def __init__(self, problem: str, mark, path: str = "") -> None:
        super().__init__(problem=problem, problem_mark=mark)
        self.path = path


def _show_tag(tag: str) -> str:
    return "!!" + tag[len(_TAG) :] if tag.startswith(_TAG) else tag


def _join(path: str, key: Any) -> str:
    return f"{path}.{key}" if path else str(key)


class SafeLoader(yaml.SafeLoader):
    """PyYAML's SafeLoader with limits for files from strangers.

    Nesting at most ``MAX_DEPTH`` and at most ``MAX_NODES`` values, both counted again for every
    alias (no billion laughs, no recursive aliases); duplicate keys are errors naming the key path
    and line (PyYAML keeps the last silently); keys are text; only the tags of plain values, lists
    and mappings (and ``<<`` merge keys); integers of at most ``MAX_DIGITS`` digits. Dates stay text.
    """

    yaml_implicit_resolvers = {
        first: [(tag, regexp) for tag, regexp in resolvers if tag != _TAG + "timestamp"]
        for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
    }

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self._depth = 0
        self._composed = 0
        self._paths: dict[int, str] = {}  # node id -> key path where it first appears
        self._explicit: dict[int, set[int]] = {}  # mapping node id -> ids of keys written in it

    # --- while scanning: PyYAML's scanner slows down quadratically with open brackets ------------
    def fetch_flow_collection_start(self, TokenClass):
        if self.flow_level >= MAX_DEPTH:
            raise _YAMLLimit(f"nested more than {MAX_DEPTH} deep", self.get_mark())
        super().fetch_flow_collection_start(TokenClass)

    # --- while composing: nesting and count, before anything deeper is parsed ------------------
    def compose_node(self, parent, index):
        self._depth += 1
        self._composed += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _YAMLLimit(f"nested more than {MAX_DEPTH} deep", self.peek_event().start_mark)
            if self._composed > MAX_NODES:
                raise _YAMLLimit(f"more than {MAX_NODES} values", self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def get_single_node(self):
        node = super().get_single_node()
        if node is not None:
            self._inspect(node, 1, "", set(), {})
        return node

    # --- after composing: every node once, aliases expanded by size ----------------------------
    def _inspect(self, node, depth: int, path: str, active: set[int], memo: dict) -> tuple[int, int]:
        """Check ``node`` and return (values, height) of its expansion."""
        key = id(node)
        if key in active:
            raise _YAMLLimit("an alias refers to its own anchor (a recursive structure)", node.start_mark, path)
        if depth > MAX_DEPTH:
            raise _YAMLLimit(f"nested more than {MAX_DEPTH} deep (after expanding aliases)", node.start_mark, path)
        if key not in memo:
            self._paths.setdefault(key, path)
            active.add(key)
            memo[key] = self._measure(node, depth, path, active, memo)
            active.discard(key)
        size, height = memo[key]
        if depth - 1 + height > MAX_DEPTH:
            raise _YAMLLimit(f"nested more than {MAX_DEPTH} deep (after expanding aliases)", node.start_mark, path)
        return size, height

    def _measure(self, node, depth: int, path: str, active: set[int], memo: dict) -> tuple[int, int]:
        expected = {ScalarNode: _SCALAR_TAGS, SequenceNode: {_TAG + "seq"}, MappingNode: {_TAG + "map"}}
        if node.tag not in expected[type(node)]:
            raise _YAMLLimit(
                f"tag `{_show_tag(node.tag)}` is not allowed; expected plain values, lists and mappings",
                node.start_mark,
                path,
            )
        if isinstance(node, ScalarNode):
            digits = sum(c.isdigit() for c in node.value)
            if node.tag == _TAG + "int" and digits > MAX_DIGITS:
                raise _YAMLLimit(f"an integer of {digits} digits; expected at most {MAX_DIGITS}", node.start_mark, path)
            return 1, 1
        if isinstance(node, SequenceNode):
            children = [(_join(path, i), item) for i, item in enumerate(node.value)]
        else:
            children = []
            explicit = set()
            for key_node, value in node.value:
                if key_node.tag == _MERGE:
                    children.append((path, value))
                    continue
                if not isinstance(key_node, ScalarNode) or key_node.tag != _TAG + "str":
                    shown = key_node.value if isinstance(key_node, ScalarNode) else _KINDS[type(key_node)]
                    read_as = _show_tag(key_node.tag).removeprefix("!!")
                    raise _YAMLLimit(
                        f"key {shown!r} is read as {read_as}; expected a text key (quote it: '{shown}')"
                        if isinstance(key_node, ScalarNode)
                        else f"a key is {shown}; expected a text key",
                        key_node.start_mark,
                        path,
                    )
                explicit.add(id(key_node))
                children.append((_join(path, key_node.value), value))
            self._explicit[id(node)] = explicit
        size, height = 1, 1
        for child_path, child in children:
            child_size, child_height = self._inspect(child, depth + 1, child_path, active, memo)
            size += child_size + 1
            height = max(height, child_height + 1)
            if size > MAX_NODES:
                raise _YAMLLimit(
                    f"expands to more than {MAX_NODES} values (aliases count their anchor's again)",
                    node.start_mark,
                    path,
                )
        return size, height

    # --- constructing: duplicate keys, and any error with its line --------------------------
    def construct_mapping(self, node, deep=False):
        if not isinstance(node, MappingNode):
            raise ConstructorError(None, None, f"expected a mapping; got {_KINDS.get(type(node))}", node.start_mark)
        explicit = self._explicit.get(id(node), set())
        self.flatten_mapping(node)  # merge keys: their pairs first, then the ones written here
        path = self._paths.get(id(node), "")
        mapping: dict = {}
        written: dict = {}  # key -> line where it was written in this mapping
        for key_node, value_node in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                hash(key)
            except TypeError:
                raise ConstructorError(None, None, "a key is not a plain value", key_node.start_mark) from None
            line = key_node.start_mark.line + 1
            if id(key_node) in explicit:
                if key in written:
                    raise _YAMLLimit(
                        f"duplicate key (first at {written[key]}); expected each key once in a mapping",
                        key_node.start_mark,
                        _join(path, key),
                    )
                written[key] = f"line {line}, column {key_node.start_mark.column + 1}"
            mapping[key] = self.construct_object(value_node, deep=deep)
        return mapping

    def construct_object(self, node, deep=False):
        try:
            return super().construct_object(node, deep)
        except (yaml.YAMLError, RecursionError, MemoryError):
            raise
        except Exception as exc:  # e.g. `!!int abc`, `!!bool maybe`
            raise ConstructorError(
                None, None, f"cannot read {_short(node.value)}: {type(exc).__name__}: {exc}", node.start_mark
            ) from None


def _codepoint(character: int | str) -> str:
    return f"U+{character if isinstance(character, int) else ord(character):04X}"


def _where(mark) -> str:
    return f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""


def parse_yaml(data: bytes, file: str) -> Any:
    """Decode ``data`` as UTF-8 and parse it with :class:`SafeLoader`; raises :class:`ScenarioError`."""
    if len(data) > MAX_BYTES:
        raise ScenarioError(file, [Problem("", f"expected at most {MAX_BYTES} bytes of YAML; got {len(data)}")])
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]  # a UTF-8 byte order mark
    try:
        text = data.decode("utf-8", errors="strict")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise ScenarioError(
            file,
            [
                Problem(
                    "",
                    f"line {line}, column {column} (byte {exc.start}): expected UTF-8 text; "
                    f"got byte 0x{data[exc.start]:02x} ({exc.reason})",
                )
            ],
        ) from None
    loader = None
    try:
        loader = SafeLoader(text)
        return loader.get_single_data()
    except _YAMLLimit as exc:
        raise ScenarioError(file, [Problem(exc.path, f"{_where(exc.problem_mark)}{exc.problem}")]) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        what = exc.problem or exc.context
        raise ScenarioError(file, [Problem("", f"{_where(mark)}not valid YAML: {what}")]) from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        column = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        raise ScenarioError(
            file,
            [
                Problem(
                    "",
                    f"line {line}, column {column}: not valid YAML: "
                    f"character {_codepoint(exc.character)} is not allowed",
                )
            ],
        ) from None
    except yaml.YAMLError as exc:
        raise ScenarioError(file, [Problem("", f"not valid YAML: {exc}")]) from None
    except (RecursionError, MemoryError) as exc:  # the limits above should keep these away
        raise ScenarioError(
            file, [Problem("", f"too large or too deeply nested to read ({type(exc).__name__})")]
        ) from None
    finally:
        if loader is not None:
            loader.dispose()


def _non_finite(value: Any, path: str, out: list[Problem], depth: int = 0) -> list[Problem]:
    """Problems for every NaN or infinite number in ``value`` (a parsed scenario)."""
    if depth > 2 * MAX_DEPTH + 2:  # a deep --set path on a deep value: pydantic would refuse it anyway
        out.append(Problem(path, f"expected at most {MAX_DEPTH} levels of nesting"))
    elif isinstance(value, float) and not math.isfinite(value):
        out.append(Problem(path, f"expected a finite number; got {_short(value)}"))
    elif isinstance(value, dict):
        for key, item in value.items():
            _non_finite(item, _join(path, key), out, depth + 1)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _non_finite(item, _join(path, i), out, depth + 1)
    return out


def read_yaml(path: Path) -> dict:
    """The scenario file at ``path`` as a mapping; raises :class:`ScenarioError`."""
    file = str(path)
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size  # 0 for devices and pipes: read() below still stops
            data = b"" if size > MAX_BYTES else f.read(MAX_BYTES + 1)
    except OSError as exc:
        raise ScenarioError(file, [Problem("", f"cannot read: {exc.strerror or exc}")]) from None
    except ValueError as exc:  # e.g. a NUL byte in the path
        raise ScenarioError(file, [Problem("", f"cannot read: {exc}")]) from None
    if size > MAX_BYTES or len(data) > MAX_BYTES:
        has = f"{size} bytes" if size > MAX_BYTES else f"more than {MAX_BYTES} bytes"
        raise ScenarioError(
            file, [Problem("", f"expected a scenario of at most {MAX_BYTES // 1024} KiB; the file has {has}")]
        )
    raw = parse_yaml(data, file)
    if raw is None:
        raise ScenarioError(
            file, [Problem("", "the file is empty; expected a mapping with name, protocol, space, modules")]
        )
    if not isinstance(raw, dict):
        kind = "a list" if isinstance(raw, list) else f"the single value {_short(raw)}"
        raise ScenarioError(
            file, [Problem("", f"expected a mapping with name, protocol, space, modules at the top; got {kind}")]
        )
    return raw


# --------------------------------------------------------------------------------------------
# Overrides (--set KEY.PATH=VALUE)
# --------------------------------------------------------------------------------------------


class _BadOverride(ValueError):
    pass


def _set_path(raw: dict, dotted: str, value: Any) -> None:
    """Set ``raw[a][b]...`` for ``dotted`` 'a.b...': missing mappings are created, list entries must
    exist, and a plain value on the way is an error (not silently replaced)."""
    parts = dotted.split(".")
    if not all(parts):
        raise _BadOverride(f"expected KEY.PATH of dot-separated keys; got {dotted!r}")
    if len(parts) > MAX_DEPTH:
        raise _BadOverride(f"expected a KEY.PATH of at most {MAX_DEPTH} keys; got {len(parts)}")
    node: Any = raw
    for i, part in enumerate(parts):
        parent = ".".join(parts[:i]) or "the scenario"
        if isinstance(node, list):
            if not (part.isdecimal() and int(part) < len(node)):
                valid = f"an index 0..{len(node) - 1}" if node else "no index (it is empty)"
                raise _BadOverride(f"{parent} is a list of {len(node)}; expected {valid}; got {part!r}")
            part = int(part)
        elif not isinstance(node, dict):
            raise _BadOverride(f"{parent} is {_short(node)}, not a mapping or list; cannot set {part!r} in it")
        elif ".".join(parts[i:]) in node or parts[:i] == ["conditions"]:  # keys with dots: body.slope_deg
            node[".".join(parts[i:])] = value
            return
        if i == len(parts) - 1:
            node[part] = value
            return
        child = node[part] if isinstance(node, list) else node.get(part)
        if child is None:
            child = node[part] = {}
        node = child


def apply_overrides(raw: dict, overrides: list[str], file: str) -> dict:
    """Apply ``KEY.PATH=VALUE`` overrides (VALUE parsed as YAML, with the same limits)."""
    raw = copy.deepcopy(raw)
    for item in overrides:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ScenarioError(file, [Problem("--set", f"expected KEY.PATH=VALUE; got {item!r}")])
        try:
            value = parse_yaml(text.encode("utf-8", errors="surrogateescape"), f"--set {key}")
            _set_path(raw, key, value)
        except ScenarioError as exc:
            raise ScenarioError(
                file, [Problem(f"--set {key}", p.message, p.suggestion) for p in exc.problems]
            ) from None
        except _BadOverride as exc:
            raise ScenarioError(file, [Problem(f"--set {key}", str(exc))]) from None
    return raw
