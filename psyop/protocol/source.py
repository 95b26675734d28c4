"""Read protocol YAML into plain data plus the line/column of every key and value.

The text is composed into PyYAML's node tree (which keeps marks), constructed with the safe
constructor, and walked once to record, for each key path such as ``("scene", 0, "size_deg")``,
where its value starts and where its key is written. Validation errors are mapped back to
those positions. Duplicate keys, which PyYAML would silently overwrite, are reported here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import yaml

from psyop.errors import UserError

Path = tuple[Any, ...]  # Any: YAML mapping keys may be any scalar (str, int, float, bool)

#: libyaml's parser when available (about 30x faster, same node tree and marks).
_Loader: type = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


@dataclass(frozen=True)
class Mark:
    """A 1-based line and column in the protocol file."""

    line: int
    column: int


@dataclass(frozen=True)
class YamlDocument:
    """Constructed data and the marks of every value (``value_marks``) and key (``key_marks``)."""

    data: Any  # Any: the parsed YAML document, validated by the pydantic models
    source_name: str
    value_marks: dict[Path, Mark] = field(default_factory=dict)
    key_marks: dict[Path, Mark] = field(default_factory=dict)
    containers: set[Path] = field(default_factory=set)

    def location(self, mark: Mark | None) -> str:
        return f"{self.source_name}:{mark.line}:{mark.column}" if mark else self.source_name

    def nearest(self, path: Path, *, key: bool = False) -> tuple[Path, Mark | None]:
        """The longest prefix of ``path`` that exists in the file, and its mark.

        A mapping or list is located at its key (``design:``), a scalar at its value, and with
        ``key=True`` anything at its key. Elements that are not in the file (pydantic's union tags such as ``disc`` or
        ``InlineDisplayProfile``) are skipped, so ``("scene", 0, "disc", "size_deg")`` maps to
        ``("scene", 0, "size_deg")``."""
        found: Path = ()
        for element in path:
            candidate = found + (element,)
            if candidate in self.value_marks:
                found = candidate
        at_key = (key or found in self.containers) and found in self.key_marks
        marks = self.key_marks if at_key else self.value_marks
        return found, marks.get(found)


def _mark(node: yaml.Node) -> Mark:
    return Mark(node.start_mark.line + 1, node.start_mark.column + 1)


def format_path(path: Path) -> str:
    """``("scene", 0, "size_deg")`` -> ``scene[0].size_deg``."""
    text = ""
    for element in path:
        if isinstance(element, int) and not isinstance(element, bool):
            text += f"[{element}]"
        else:
            text += ("." if text else "") + str(element)
    return text or "(top level)"


def _walk(loader: yaml.SafeLoader, node: yaml.Node, path: Path, doc: YamlDocument, seen: set[int], depth: int) -> None:
    if depth > 200:
        raise UserError("the protocol is nested more than 200 levels deep; flatten it", doc.location(_mark(node)))
    doc.value_marks.setdefault(path, _mark(node))
    _check_tag(loader, node, doc)
    if id(node) in seen:  # an alias: marks of the anchor already recorded
        return
    seen.add(id(node))
    if isinstance(node, (yaml.MappingNode, yaml.SequenceNode)):
        doc.containers.add(path)
    if isinstance(node, yaml.MappingNode):
        keys: dict[Any, Mark] = {}  # Any: a YAML key of any scalar type
        for key_node, value_node in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue  # `<<: *anchor`: merged keys may be overridden; their marks stay at the anchor
            key = _construct_key(loader, key_node, doc)
            try:
                hash(key)
            except TypeError:
                raise UserError("a key must be a plain word, not a list or mapping", doc.location(_mark(key_node))) from None
            if key in keys:
                first = keys[key]
                raise UserError(
                    f"duplicate key '{key}' in {format_path(path)} (first written at line {first.line}, column "
                    f"{first.column}); YAML would silently keep only the last one. Delete or merge one of them.",
                    doc.location(_mark(key_node)),
                )
            keys[key] = _mark(key_node)
            doc.key_marks.setdefault(path + (key,), _mark(key_node))
            _walk(loader, value_node, path + (key,), doc, seen, depth + 1)
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            _walk(loader, item, path + (index,), doc, seen, depth + 1)
    else:
        _check_scalar(loader, node, doc)


def _construct_key(loader: yaml.SafeLoader, key_node: yaml.Node, doc: YamlDocument) -> Any:  # Any: a YAML key
    """The key's value; a tagged or unreadable key (``!!timestamp foo: 1``, ``!!set [1]: 1``) is
    one located line, as a value is (the constructor's own message spans lines and names no file)."""
    _check_tag(loader, key_node, doc)
    if isinstance(key_node, yaml.ScalarNode):
        _check_scalar(loader, key_node, doc)
    try:
        return loader.construct_object(key_node, deep=True)
    except _CONSTRUCT_ERRORS as error:
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise UserError(f"cannot read this key ({str(problem)[:160]}); a key is a plain word such as `size_deg:`",
                        doc.location(_mark(key_node))) from None


#: explicit tags a protocol may carry (``!!str 12`` keeps a number as text); any other explicit tag
#: (``!!binary``, ``!!set``, ``!!omap``, ``!!timestamp``, ``!!python/...``, ``!foo``) makes a value
#: no protocol field takes, so it is refused at the value with one line
_PLAIN_TAGS = frozenset(f"tag:yaml.org,2002:{name}" for name in ("str", "int", "float", "bool", "null", "seq", "map"))


#: the node kind each plain tag constructs (``!!str [1]`` is refused at the value, not as a syntax error)
_TAG_NODES = {"seq": yaml.SequenceNode, "map": yaml.MappingNode}


def _check_tag(loader: yaml.SafeLoader, node: yaml.Node, doc: YamlDocument) -> None:
    if node.tag in _PLAIN_TAGS:
        name = str(node.tag).rsplit(":", 1)[-1]
        wanted = _TAG_NODES.get(name, yaml.ScalarNode)
        if not isinstance(node, wanted):
            what = {"seq": "a list", "map": "a mapping"}.get(name, "a single value")
            raise UserError(f"the YAML tag !!{name} makes {what}, but a {node.id} follows it; remove the tag",
                            doc.location(_mark(node)))
        return
    value = node.value if isinstance(node, yaml.ScalarNode) else None
    if node.tag == loader.resolve(type(node), value, (True, False)):
        return  # resolved from the plain text (a date, a merge key `<<`), not written as a tag
    tag = str(node.tag)
    shown = "!!" + tag.removeprefix("tag:yaml.org,2002:") if tag.startswith("tag:yaml.org,2002:") else tag
    raise UserError(f"the YAML tag {shown} is not used in psyop protocols; remove the tag and write the value "
                    "plainly (quote it to keep it as text)", doc.location(_mark(node)))


#: what a scalar's constructor may raise on a bad value (``!!int abc``, ``!!bool maybe``,
#: ``2020-02-30``, a 5000-digit integer): reported at the value, never as a traceback
_CONSTRUCT_ERRORS = (ValueError, KeyError, TypeError, OverflowError, ArithmeticError, AttributeError, yaml.YAMLError)


def _check_scalar(loader: yaml.SafeLoader, node: yaml.Node, doc: YamlDocument) -> None:
    try:
        loader.construct_object(node)
    except _CONSTRUCT_ERRORS as error:
        raise _value_error(node, error, doc.location(_mark(node))) from None


def _value_error(node: yaml.Node, error: BaseException, location: str) -> UserError:
    tag = str(node.tag).rsplit(":", 1)[-1]
    tag = {"int": "an integer", "float": "a number", "bool": "true/false", "timestamp": "a date",
           "null": "null"}.get(tag, f"a {tag}")
    value = str(node.value)
    shown = repr(value) if len(value) <= 40 else f"{value[:40]!r}... ({len(value)} characters)"
    detail = str(error) if isinstance(error, (ValueError, TypeError, OverflowError)) else type(error).__name__
    if tag == "true/false":
        detail = "write true or false"
    if "digits" in detail and "integer string conversion" in detail:
        detail = f"a number with {len(value)} digits is far too long"
    return UserError(f"cannot read {shown} as {tag} ({detail[:160]}); write a valid value or quote it as text",
                     location)


def _codepoint(character: int | str) -> int:
    return character if isinstance(character, int) else ord(str(character)[:1] or "\0")


def _syntax_error(error: yaml.YAMLError, source_name: str, text: str) -> UserError:
    mark = getattr(error, "problem_mark", None) or getattr(error, "context_mark", None)
    if isinstance(error, yaml.reader.ReaderError):
        before = text[: error.position]
        line = before.count("\n") + 1
        column = error.position - (before.rfind("\n") + 1) + 1
        return UserError(
            f"YAML cannot contain the character U+{_codepoint(error.character):04X} here; remove it or quote the text "
            "(protocols are UTF-8 text files)",
            f"{source_name}:{line}:{column}",
        )
    problem = getattr(error, "problem", None) or str(error)
    context = getattr(error, "context", None)
    detail = f"{context}, {problem}" if context else problem
    context_mark = getattr(error, "context_mark", None)
    if context and context_mark is not None and mark is not None and context_mark.line != mark.line:
        detail += f" (it started at line {context_mark.line + 1}, column {context_mark.column + 1})"
    location = f"{source_name}:{mark.line + 1}:{mark.column + 1}" if mark else source_name
    hint = "Check the indentation, colons and quotes on this line and the one before it."
    if mark is not None:
        lines = text.splitlines()
        if mark.line < len(lines) and "\t" in lines[mark.line]:
            hint = "YAML does not allow tabs for indentation; indent with spaces."
    return UserError(f"YAML syntax error: {detail}. {hint}", location)


def read_yaml(text: str, source_name: str) -> YamlDocument:
    """Parse ``text``; raise :class:`UserError` (with file:line:column) on any YAML problem."""
    try:
        loader = _Loader(text)
    except yaml.YAMLError as error:
        raise _syntax_error(error, source_name, text) from None
    except UnicodeError:
        raise UserError("the protocol contains characters that are not valid Unicode text; save it as UTF-8",
                        source_name) from None
    try:
        try:
            node = loader.get_single_node()
            if node is None:
                raise UserError("the protocol is empty; start from one in protocols/ (see docs/protocols.md)",
                                f"{source_name}:1:1")
            if not isinstance(node, yaml.MappingNode):
                raise UserError(
                    "a protocol is a mapping of sections (study:, display:, scene:, ...), but this file holds a "
                    f"{node.id}; start from one in protocols/",
                    f"{source_name}:{_mark(node).line}:{_mark(node).column}",
                )
            # marks and duplicate keys first, on the raw node tree (before merge keys are flattened)
            document = YamlDocument(data=None, source_name=source_name)
            _walk(loader, node, (), document, set(), 0)
            data = loader.construct_document(node)
        except yaml.YAMLError as error:
            raise _syntax_error(error, source_name, text) from None
        except _CONSTRUCT_ERRORS[:-1] as error:  # a value _walk did not see (e.g. behind a merge key)
            raise UserError(f"cannot read a value: {str(error)[:160]}", source_name) from None
        except RecursionError:
            raise UserError("the protocol is nested too deeply to read; flatten it", source_name) from None
        return YamlDocument(data, source_name, document.value_marks, document.key_marks, document.containers)
    finally:
        loader.dispose()
