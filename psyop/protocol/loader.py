"""Load a protocol file: YAML -> validated :class:`Protocol`, or a :class:`UserError` that says
where (file:line:column), which key, and what to do."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from pydantic import ValidationError

from psyop.errors import UserError
from psyop.input_files import InputFile
from psyop.protocol.messages import format_validation_error
from psyop.protocol.model import Protocol
from psyop.protocol.semantics import check_protocol
from psyop.protocol.source import format_path, read_yaml

if TYPE_CHECKING:
    from psyop.mesh.load import MeshFiles


def parse_protocol(text: str, source_name: str = "<protocol>", base_dir: Path | None = None,
                   meshes: MeshFiles | None = None) -> Protocol:
    """Validate protocol YAML ``text``. ``source_name`` appears in messages; relative texture
    paths are resolved against ``base_dir`` (default: the folder of ``source_name`` when that is
    a file, else the working directory). ``meshes``: the command's model cache (psyop.mesh.MeshFiles)
    the mesh items are read into, for the session to reuse (None: a fresh one for this check)."""
    if base_dir is None:
        candidate = Path(source_name)
        base_dir = candidate.parent if candidate.is_file() else None
    document = read_yaml(text, source_name)
    try:
        protocol = Protocol.model_validate(document.data)
    except ValidationError as error:
        location, message = format_validation_error(error, document, Protocol)
        raise UserError(message, location) from None
    issues = check_protocol(protocol, base_dir, meshes)
    if issues:
        lines = []
        first = None
        for issue in issues[:8]:
            path, mark = document.nearest(issue.path)
            location = document.location(mark)
            first = first or location
            lines.append((location, f"at {format_path(issue.path)}: {issue.message}"))
        message = "\n".join([lines[0][1], *(f"{loc}: {text}" for loc, text in lines[1:])])
        if len(issues) > 8:
            message += f"\n... and {len(issues) - 8} more problems"
        raise UserError(message, first)
    protocol._source_text = text
    protocol._source_name = source_name
    return protocol


#: the largest protocol file read (real ones are a few kB); bounds memory for any input
MAX_PROTOCOL_BYTES = 1 << 20

PROTOCOL_FILE = InputFile(
    what="the protocol file", give="give a protocol .yaml file", max_bytes=MAX_PROTOCOL_BYTES,
    typical="a protocol is a few kB of YAML",
    not_found="protocol file not found: {path}; check the path (protocols live in protocols/)")


def read_protocol_bytes(path: Path) -> bytes:
    """The file's bytes: a regular file of at most :data:`MAX_PROTOCOL_BYTES`, else a UserError
    (a FIFO or a device is refused from ``stat`` before it is opened: psyop.input_files)."""
    return PROTOCOL_FILE.read_bytes(path)


def load_protocol(path: str | Path, meshes: MeshFiles | None = None) -> Protocol:
    """Read and validate the protocol file at ``path`` (``meshes``: as :func:`parse_protocol`)."""
    path = Path(path)
    raw = read_protocol_bytes(path)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        before = raw[: error.start]
        line = before.count(b"\n") + 1
        column = error.start - (before.rfind(b"\n") + 1) + 1
        raise UserError("this file is not UTF-8 text; save it as UTF-8 (protocols are YAML text files)",
                        f"{path}:{line}:{column}") from None
    return parse_protocol(text, str(path), base_dir=path.parent, meshes=meshes)
