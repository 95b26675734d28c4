"""Checking that an image texture a protocol names can be decoded, at validation time.

``psyop validate`` (psyop.protocol.semantics) calls :func:`check_image_file` for every image
surface, so a file that is not an image (a text file named ``checker.png``, a truncated PNG)
is refused with one located line before a session starts, not in ``run``, ``render`` or
``audit``. The file is read with bounded memory (:class:`psyop.input_files.InputFile`) and
fully decoded by Pillow, the decoder matplotlib's ``imread`` (the renderer's,
psyop.rendering.textures) uses for PNG and JPEG.
"""

from __future__ import annotations

import io
from pathlib import Path

from psyop.errors import UserError
from psyop.input_files import InputFile
from psyop.limits import MAX_IMAGE_FILE_BYTES, MAX_TEXTURE_SIDE_PX


def check_image_file(path: Path, shown: str) -> None:
    """Refuse ``path`` unless it is a decodable image within the size limits.

    ``shown`` is the name the protocol gives the file (its ``path``), used in messages.
    Raises :class:`UserError` with a one-line message saying what is wrong and the fix.
    """
    from PIL import Image

    reader = InputFile(what=f"texture file '{shown}'", give="an image surface's path must name an image file",
                       max_bytes=MAX_IMAGE_FILE_BYTES, typical="downscale the image",
                       not_found=f"texture file '{shown}' not found (looked for {{path}}); paths are relative to "
                                 "the protocol file. Fix the path or add the file.")
    raw = reader.read_bytes(path)
    try:
        with Image.open(io.BytesIO(raw)) as image:
            width, height = image.size
            if max(width, height) > MAX_TEXTURE_SIDE_PX:
                raise UserError(f"texture file '{shown}' is {width} x {height} px, over psyop's "
                                f"{MAX_TEXTURE_SIDE_PX} px per side; downscale it")
            image.load()
    except UserError:
        raise
    except Exception as error:  # noqa: BLE001 - Pillow raises many types for a bad file; all are the user's input
        raise UserError(f"texture file '{shown}' is not a readable image ({type(error).__name__}: {error}); "
                        "give a PNG or JPEG file") from None
