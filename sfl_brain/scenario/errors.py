"""A scenario's problems as the user reads them: ``FILE: key.path: expected ..., got ... (did you mean ...?)``,
from a pydantic validation error or from a check of ours (:class:`Problem`, :class:`ScenarioError`)."""

from __future__ import annotations

import math
import re
import typing
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel, ValidationError

from ..proposers import PROPOSERS
from ..registry import nearest

# --------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------


@dataclass
class Problem:
    path: str
    message: str
    suggestion: str | None = None

    def render(self, file: str) -> str:
        hint = f" (did you mean `{self.suggestion}`?)" if self.suggestion else ""
        where = f"{self.path}: " if self.path else ""
        return f"{file}: {where}{self.message}{hint}"


class ScenarioError(Exception):
    """One or more problems in a scenario file; ``str()`` lists them all."""

    def __init__(self, file: str, problems: list[Problem]) -> None:
        self.file = file
        self.problems = problems
        super().__init__("\n".join(p.render(file) for p in problems))


def _dotted(loc: tuple) -> str:
    return ".".join(str(x) for x in loc)


def _short(value: Any) -> str:
    """A value as the user wrote it in YAML (true, null, .inf), cut to 60 characters."""
    if value is None or isinstance(value, bool):
        text = {None: "null", True: "true", False: "false"}[value]
    elif isinstance(value, float) and not math.isfinite(value):
        text = ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf")
    else:
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


#: what a pydantic type error expected, in words
EXPECTED = {
    "int_type": "an integer",
    "int_from_float": "an integer",
    "float_type": "a number",
    "bool_type": "true or false",
    "string_type": "text",
    "list_type": "a list",
    "tuple_type": "a list",
    "dict_type": "a mapping",
    "model_type": "a mapping",
    "model_attributes_type": "a mapping",
    "finite_number": "a finite number",
}


def _unquoted(given: Any, kind: str) -> str | None:
    """The number a quoted string would be without its quotes (for did-you-mean), if it is one."""
    if not isinstance(given, str) or kind not in ("int_type", "float_type"):
        return None
    try:
        number = int(given) if kind == "int_type" else float(given)
    except ValueError:
        return None
    return given.strip() if math.isfinite(number) else None


def _models_of(annotation) -> list[type[BaseModel]]:
    """The models an annotation holds: itself, or those inside a list, dict, union or Annotated."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models_of(arg)]


def _fields_at(model: type[BaseModel], loc: tuple) -> list[str]:
    """Valid keys at ``loc`` inside ``model`` (for did-you-mean on unknown keys). ``loc`` keeps the kind tags of
    discriminated unions (``protocol.conditions.analyses.0.trace``), which choose the branch; without one, the
    keys of every branch."""
    current: Any = model
    for part in loc:
        if isinstance(current, type) and issubclass(current, BaseModel):
            f = current.model_fields.get(str(part))
            if f is None:
                return []
            current = f.annotation
            continue
        models = _models_of(current)
        tagged = [
            m
            for m in models
            if "kind" in m.model_fields and str(part) in typing.get_args(m.model_fields["kind"].annotation)
        ]
        named = [m for m in models if str(part) in m.model_fields]
        if tagged:  # a discriminated union's kind tag
            current = tagged[0]
        elif named:
            current = named[0].model_fields[str(part)].annotation
        elif len(models) == 1:  # a list index or a dict key: the item's model
            current = models[0]
    models = _models_of(current)
    return (
        sorted({name for m in models for name in m.model_fields})
        if len(models) > 1
        else (list(models[0].model_fields) if models else [])
    )


#: parts pydantic inserts into an error's location: validators and unions (not keys of the file)
_SCHEMA_PART = re.compile(
    r"^(function-(after|before|wrap|plain)|tagged-union|union|nullable|lax-or-strict|json-or-python|chain|"
    r"definition-ref|constrained-\w+|list|dict|tuple|set|frozenset)\[.*\]$"
)
_UNION_MEMBERS = ("float", "int", "str", "bool")


def _clean_loc(loc: tuple, kind: str) -> tuple:
    """An error's location as a key path of the file: without validator names, the protocol's
    kind tag (``protocol.learn.trials``) and, for a type error, the member type of a union
    (``conditions.body.x.float``)."""
    out: list = []
    for part in loc:
        if isinstance(part, str) and _SCHEMA_PART.match(part):
            continue
        if len(out) == 1 and out[0] == "protocol" and part in ("learn", "sweep", "exploit", "conditions"):
            continue
        if (
            len(out) >= 2
            and out[-2] == "analyses"
            and part in ("poincare", "trace", "pattern_space", "command_jump", "detection")
        ):  # an analysis's kind tag
            continue
        if out == ["protocol", "proposer"] and part in PROPOSERS:  # a proposer's kind tag
            continue
        out.append(part)
    if kind in EXPECTED and len(out) > 1 and out[-1] in _UNION_MEMBERS:
        out.pop()
    return tuple(out)


def problems_from(exc: ValidationError, model: type[BaseModel], prefix: tuple = ()) -> list[Problem]:
    out = []
    type_errors: dict[str, list] = {}  # path -> type errors there (a union gives one per member)
    for err in exc.errors():
        kind = err["type"]
        clean = _clean_loc(tuple(err["loc"]), kind)
        path = _dotted(prefix + clean)
        given = err.get("input")
        if kind in EXPECTED and path in type_errors:
            type_errors[path].append(kind)
            continue
        if kind == "extra_forbidden":
            tagged = tuple(p for p in err["loc"] if not (isinstance(p, str) and _SCHEMA_PART.match(p)))
            valid = _fields_at(model, tagged[:-1])
            out.append(Problem(path, f"unknown key; expected one of {sorted(valid)}", nearest(str(clean[-1]), valid)))
        elif kind == "missing":
            out.append(Problem(path, "required key is missing"))
        elif kind == "literal_error":
            allowed = err.get("ctx", {}).get("expected", "")
            options = [o.strip().strip("'") for o in allowed.replace(" or ", ",").split(",") if o.strip()]
            out.append(Problem(path, f"expected one of {allowed}; got {_short(given)}", nearest(str(given), options)))
        elif kind == "union_tag_not_found":  # a protocol without its kind
            ctx = err.get("ctx", {})
            out.append(
                Problem(
                    _dotted((*prefix, *clean, ctx.get("discriminator", "kind").strip("'"))), "required key is missing"
                )
            )
        elif kind == "union_tag_invalid":
            ctx = err.get("ctx", {})
            tags = [t.strip().strip("'") for t in str(ctx.get("expected_tags", "")).split(",")]
            discriminator = str(ctx.get("discriminator", "kind")).strip("'")
            # the tag as written (pydantic's context has it as a string: an empty value would read 'None')
            tag = given.get(discriminator) if isinstance(given, dict) else ctx.get("tag")
            out.append(
                Problem(
                    path + ".kind" if path else "kind",
                    f"expected one of {ctx.get('expected_tags')}; got {_short(tag)}",
                    nearest(str(tag), tags) if tag is not None else None,
                )
            )
        elif kind in EXPECTED:
            type_errors[path] = [kind]
            out.append(Problem(path, f"expected {EXPECTED[kind]}; got {_short(given)}", _unquoted(given, kind)))
        else:
            msg = err["msg"]
            if msg.startswith("Value error, "):
                msg = msg[len("Value error, ") :]
            got = "" if isinstance(given, dict) else f"; got {_short(given)}"  # a whole model: too long
            out.append(Problem(path, f"{msg[0].lower() + msg[1:]}{got}"))
    for problem in out:  # a union: one problem naming every type it takes
        kinds = [EXPECTED[k].replace("true or false", "true/false") for k in type_errors.get(problem.path, ())]
        kinds = [k for k in dict.fromkeys(kinds) if not (k == "an integer" and "a number" in kinds)]
        if len(kinds) > 1 and problem.message.startswith("expected "):
            got = problem.message.split("; got ", 1)[1]
            problem.message = f"expected {', '.join(kinds[:-1])} or {kinds[-1]}; got {got}"
    return out
