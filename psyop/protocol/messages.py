"""Turn pydantic validation errors into messages a person can act on.

Each error becomes ``file:line:column: at <key path>: <what is wrong>. <what to do>``. Unknown
keys get a "did you mean" from the keys the model at that place allows (difflib). Errors that
land on the same place (pydantic tries each member of a union) are merged into one line.
"""

from __future__ import annotations

import difflib
import re
import types
import typing
from typing import Any

from pydantic import BaseModel, ValidationError
from pydantic_core import ErrorDetails

from psyop.protocol.source import Path, YamlDocument, format_path
from psyop.records import Loc

MAX_REPORTED = 8
_BOUNDS = {"greater_than": "greater than", "greater_than_equal": "at least", "less_than": "less than",
           "less_than_equal": "at most"}
_BOUND_KEYS = {"greater_than": "gt", "greater_than_equal": "ge", "less_than": "lt", "less_than_equal": "le"}


def _candidates(tp: Any) -> list[Any]:  # Any: typing annotations (unions, Annotated, models)
    """Flatten Annotated / Union / Optional into the member types."""
    origin = typing.get_origin(tp)
    if origin is typing.Annotated:
        return _candidates(typing.get_args(tp)[0])
    if origin in (typing.Union, types.UnionType):
        out: list[Any] = []  # Any: typing annotations
        for arg in typing.get_args(tp):
            out += _candidates(arg)
        return out
    return [tp]


def _kind_tag(model: type[BaseModel]) -> str | None:
    field = model.model_fields.get("kind")
    if field is None:
        return None
    args = typing.get_args(field.annotation)
    return args[0] if args else None


def models_at(root: type[BaseModel], loc: Loc) -> list[type[BaseModel]]:
    """The model classes that could be validating the mapping at ``loc``."""
    current: list[Any] = [root]  # Any: models or typing annotations along the path
    for element in loc:
        nxt: list[Any] = []  # Any: the same, one level deeper
        for tp in current:
            for candidate in _candidates(tp):
                origin = typing.get_origin(candidate)
                if isinstance(candidate, type) and issubclass(candidate, BaseModel):
                    if isinstance(element, str) and element in candidate.model_fields:
                        nxt.append(candidate.model_fields[element].annotation)
                    elif element in (candidate.__name__, _kind_tag(candidate)):
                        nxt.append(candidate)  # pydantic's union tag: stay on this model
                elif origin in (list, tuple) and isinstance(element, int):
                    args = [a for a in typing.get_args(candidate) if a is not Ellipsis]
                    nxt += args[:1] if origin is list else args[element:element + 1]
                elif origin is dict:
                    nxt.append(typing.get_args(candidate)[1])
                elif origin is typing.Literal or candidate in (str, float, int, bool):
                    if element == getattr(candidate, "__name__", None):
                        nxt.append(candidate)
        current = nxt
    return [c for tp in current for c in _candidates(tp) if isinstance(c, type) and issubclass(c, BaseModel)]


def _allowed_keys(root: type[BaseModel], loc: Loc) -> list[str]:
    keys: list[str] = []
    for model in models_at(root, loc):
        keys += [k for k in model.model_fields if k not in keys]
    return keys


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _describe(root: type[BaseModel], error: ErrorDetails) -> tuple[str, bool]:
    """(message with a hint, whether it points at a key rather than a value)."""
    kind = error["type"]
    loc = tuple(error["loc"])
    message = str(error["msg"])
    if message.startswith("Value error, "):
        message = message[len("Value error, "):]
    if kind == "extra_forbidden":
        key = loc[-1]
        allowed = _allowed_keys(root, loc[:-1])
        close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.6)
        hint = f" Did you mean '{close[0]}'?" if close else ""
        listing = f" Allowed keys here: {', '.join(allowed)}." if allowed else ""
        return f"unknown key '{key}'.{hint}{listing} Remove or rename it.", True
    if kind == "missing":
        described = ""
        for model in models_at(root, loc[:-1]):
            field = model.model_fields.get(str(loc[-1]))
            if field is not None and field.description:
                described = f" ({field.description})"
                break
        return f"missing required key '{loc[-1]}'{described}; add '{loc[-1]}: ...' here (see docs/protocols.md)", False
    if kind in _BOUNDS:
        limit = (error.get("ctx") or {}).get(_BOUND_KEYS[kind])  # pydantic's ctx keys: gt, ge, lt, le
        return f"must be {_BOUNDS[kind]} {limit} (got {_short(error.get('input'))}); change the value", False
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        ctx = error.get("ctx") or {}
        expected = [t.strip().strip("'") for t in str(ctx.get("expected_tags", "")).split(",") if t.strip()]
        tag = ctx.get("tag")
        if kind == "union_tag_not_found":
            return f"missing 'kind:'; set it to one of {', '.join(expected)}", False
        close = difflib.get_close_matches(str(tag), expected, n=1)
        hint = f" Did you mean '{close[0]}'?" if close else ""
        return f"unknown kind '{tag}'.{hint} Kinds: {', '.join(expected)}", False
    if kind == "literal_error":
        expected_text = str((error.get("ctx") or {}).get("expected", ""))
        options = [t.strip().strip("'") for t in expected_text.replace(" or ", ",").split(",") if t.strip()]
        close = difflib.get_close_matches(str(error.get("input")), options, n=1)
        hint = f" Did you mean '{close[0]}'?" if close else ""
        return f"{_short(error.get('input'))} is not allowed here.{hint} Use one of: {', '.join(options)}", False
    message = re.sub(r"a valid dictionary or instance of (\w+)", r"a mapping of keys (\1)", message)
    message = message.replace("Input should be", "expected")
    show_input = "input" in error and not isinstance(error["input"], dict) and kind != "value_error"
    got = f" (got {_short(error['input'])})" if show_input else ""
    return f"{message}{got}", False


def format_validation_error(error: ValidationError, document: YamlDocument, root: type[BaseModel]) -> tuple[str, str]:
    """(location of the first problem, message listing every problem with its own location)."""
    merged: dict[tuple[Path, bool], list[str]] = {}
    # an unknown key usually explains a "missing" one next to it (a typo): report it first
    items = sorted(error.errors(include_url=False), key=lambda e: e["type"] != "extra_forbidden")
    for item in items:
        text, at_key = _describe(root, item)
        loc = tuple(item["loc"])
        if item["type"] == "missing":
            loc = loc[:-1]
        elif item["type"] == "union_tag_invalid":
            loc = loc + ("kind",)
        found, mark = document.nearest(loc, key=at_key)
        key = (found, at_key)
        bucket = merged.setdefault(key, [])
        if text not in bucket:
            bucket.append(text)
    lines = []
    first_location = document.source_name
    for index, ((path, at_key), texts) in enumerate(merged.items()):
        _, mark = document.nearest(path, key=at_key)
        location = document.location(mark)
        if index == 0:
            first_location = location
        joined = texts[0] if len(texts) == 1 else "; or ".join(texts)
        lines.append((location, f"at {format_path(path)}: {joined}"))
    shown = lines[:MAX_REPORTED]
    head = shown[0][1]
    rest = [f"{loc}: {text}" for loc, text in shown[1:]]
    if len(lines) > MAX_REPORTED:
        rest.append(f"... and {len(lines) - MAX_REPORTED} more problems")
    return first_location, "\n".join([head, *rest])
