"""Every field of the protocol language is used by some part of psyop, or refused at validation
(psyop.protocol.fields); and docs/protocols.md documents only fields that exist."""

from __future__ import annotations

import re
import typing
from pathlib import Path

from pydantic import BaseModel

from psyop.protocol import Protocol
from psyop.protocol.fields import FIELD_USERS, USERS

REPO = Path(__file__).resolve().parents[2]


def _models(tp: object, seen: dict[type, None]) -> dict[type, None]:
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        if tp not in seen:
            seen[tp] = None
            for field in tp.model_fields.values():
                _models(field.annotation, seen)
        return seen
    for arg in typing.get_args(tp):
        _models(arg, seen)
    return seen


def test_every_protocol_field_has_a_user_or_is_refused() -> None:
    walked = {model.__name__: set(model.model_fields) for model in _models(Protocol, {})}
    listed = {name: set(fields) for name, fields in FIELD_USERS.items()}
    assert walked == listed, "psyop/protocol/fields.py is out of date with the protocol models"
    sources = {user: "\n".join((REPO / p).read_text() for p in paths) for user, paths in USERS.items()}
    for model, fields in FIELD_USERS.items():
        for field, user in fields.items():
            assert user in USERS, (model, field, user)
            if user == "refused":  # the whole adaptive section; the refusal is tested in tests/session/test_plan_fields.py
                assert "ADAPTIVE_PROCEDURES" in sources["refused"]
                continue
            assert re.search(rf"\b{re.escape(field)}\b", sources[user]), \
                f"{model}.{field} is said to be used by {user} ({', '.join(USERS[user])}), which never names it"


def test_the_plan_compiler_reads_every_field_it_claims() -> None:
    plan_source = (REPO / "psyop" / "session" / "plan.py").read_text()
    claimed = sorted({field for fields in FIELD_USERS.values() for field, user in fields.items() if user == "plan"})
    assert claimed
    for field in claimed:
        assert re.search(rf"\.{re.escape(field)}\b", plan_source), f"psyop/session/plan.py never reads .{field}"


def test_docs_name_only_fields_of_the_language() -> None:
    """Every `key:`-looking name in docs/protocols.md's tables is a field of some protocol model."""
    docs = (REPO / "docs" / "protocols.md").read_text()
    known = {field for fields in FIELD_USERS.values() for field in fields}
    tables = [line for line in docs.splitlines() if line.startswith("|") and not line.startswith("|---")]
    named = set()
    for line in tables[1:]:
        cells = line.strip("|").split("|")
        if len(cells) < 3:
            continue
        for cell in cells[2:3]:  # the 'keys' column
            named |= set(re.findall(r"`([a-z_]+[A-Za-z_]*)`", cell))
    values = {"conventional", "ocular", "reversed", "floor", "ceiling", "left", "right", "pencil", "sphere", "cube",
              "schedule", "all", "balanced", "random", "enabled", "disabled", "a", "b", "solid", "circle"}
    unknown = sorted(n for n in named if n not in known and n not in values)
    assert not unknown, f"docs/protocols.md names keys that no protocol model has: {unknown}"
