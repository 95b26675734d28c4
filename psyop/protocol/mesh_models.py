"""Which models (file, node) a ``kind: mesh`` item can show, over every trial's factor values.

``file`` and ``node`` may be ``{factor: NAME}`` of a factor of words (psyop.protocol.scene.LevelRef):
each level is a file name (relative to the protocol file) or a node name. Validation loads every model
any trial can show (each once, psyop.mesh.MeshFiles), and session.json records all of them.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping

from psyop.protocol.conditions import expand_conditions
from psyop.protocol.model import Protocol
from psyop.protocol.scene import Mesh, Primitive, ReachMesh, ReachTarget

#: (file, node) as the protocol names them (node None: the file's whole scene)
ModelKey = tuple[str, str | None]
#: what names a model: a mesh item, or a reach target's ``object`` (both have file, node, model_for)
ModelSource = Mesh | ReachMesh


def model_source(item: Primitive) -> tuple[ModelSource, tuple[str, ...]] | None:
    """The part of a scene item that names a glTF model and its key path below the item, or None."""
    if isinstance(item, Mesh):
        return item, ()
    if isinstance(item, ReachTarget) and isinstance(item.object, ReachMesh):
        return item.object, ("object",)
    return None


def item_models(item: ModelSource, value_sets: Iterable[Mapping[str, object]]) -> dict[ModelKey, Mapping[str, object]]:
    """Each distinct (file, node) the item shows over ``value_sets``, in first-seen order, with the first
    value set that picks it (validation names its levels in a message). A fixed file and node: one entry.
    Value sets whose level is not a word are skipped (validation reports the factor's kind)."""
    if not item.word_factors:
        return {item.model_for({}): {}}
    found: dict[ModelKey, Mapping[str, object]] = {}
    for values in value_sets:
        try:
            key = item.model_for(values)
        except ValueError:
            continue
        found.setdefault(key, values)
    return found


def protocol_value_sets(protocol: Protocol) -> Iterator[dict[str, object]]:
    """Every condition, and each with the response's ``set:`` overrides of an interval (test/reference)."""
    overrides: list[dict[str, object]] = [{}]
    for role in ("test", "reference"):
        spec = getattr(protocol.response, role, None)
        values = getattr(spec, "set", None)
        if values:
            overrides.append(dict(values))
    for condition in expand_conditions(protocol.design):
        for override in overrides:
            yield {**condition, **override}


def protocol_models(protocol: Protocol) -> list[ModelKey]:
    """Every (file, node) some mesh item of the protocol can show, in scene then first-seen order."""
    models: list[ModelKey] = []
    for item in protocol.scene:
        found = model_source(item)
        if found is not None:
            source = found[0]
            sets = protocol_value_sets(protocol) if source.word_factors else iter([{}])
            models += [key for key in item_models(source, sets) if key not in models]
    return models


def level_note(item: ModelSource, values: Mapping[str, object]) -> str:
    """``"model = 'a.glb': "``: the levels that picked a model, for a message (empty for a fixed model)."""
    named = ", ".join(f"{factor} = {values.get(factor)!r}" for _, factor in item.word_factors)
    return f"{named}: " if named else ""
