"""Text for the participant: a string rasterised once to an RGB image, drawn as a textured quad.

psyop's renderer draws analytic primitives only; a line of text (the response phase's prompt,
docs/protocols.md) becomes an :class:`ImageTexture` of light ink on a dark panel, rasterised by
matplotlib's Agg canvas (already a dependency; the bundled DejaVu Sans font) and cached per string
for the session (:class:`TextImages`), like image surfaces (psyop.rendering.textures.ImageFiles).
"""

from __future__ import annotations

import hashlib
import math
import textwrap
from dataclasses import dataclass

import numpy as np

from psyop.optics.display import DisplayProfile
from psyop.rendering.scene import Colour, ImageTexture

#: Texels per em (the font size) of a rasterised string when no display is given. A session rasterises at
#: its display's central pixel density (:func:`em_px_for_display`): the texture is fetched nearest-neighbour,
#: and one texel per pixel keeps the glyphs' strokes (a finer texture drops some when minified).
EM_PX = 32
MIN_EM_PX = 8
#: Strings are wrapped at this many characters per line (on spaces).
WRAP_CHARS = 40
LINE_SPACING_EM = 1.2
#: Panel margin around the text, in em.
PADDING_EM = 0.5
INK_RGB: Colour = (1.0, 1.0, 1.0)
PANEL_RGB: Colour = (0.15, 0.15, 0.15)


@dataclass(frozen=True)
class TextImage:
    """A rasterised string: ``texture`` (ink over panel), its ``ink_fraction`` (share of texels with any ink) and
    its size in em (``width_em`` x ``height_em``, panel included: the quad's aspect ratio)."""

    text: str
    texture: ImageTexture
    ink_fraction: float
    em_px: int = EM_PX

    @property
    def width_em(self) -> float:
        return self.texture.pixels.shape[1] / self.em_px

    @property
    def height_em(self) -> float:
        return self.texture.pixels.shape[0] / self.em_px


def em_px_for_display(display: DisplayProfile, letter_height_deg: float) -> int:
    """Texels per em so that the text texture is about one texel per display pixel at the image centre
    (at least :data:`MIN_EM_PX`)."""
    px_per_tan = display.height_px / (display.tan_top - display.tan_bottom)
    return max(MIN_EM_PX, int(round(px_per_tan * 2.0 * math.tan(math.radians(letter_height_deg) / 2.0))))


def wrapped_lines(text: str, keep_lines: bool = False) -> list[str]:
    r"""The lines ``text`` is drawn in: wrapped at :data:`WRAP_CHARS` on spaces; ``keep_lines``: each of its own
    lines wrapped separately (an empty line kept), as a session screen's page is written (psyop.session.screens),
    else its line breaks are spaces (the response prompt).

    Examples
    --------
    >>> wrapped_lines("a\n\nb", keep_lines=True), wrapped_lines("a\n\nb")
    (['a', '', 'b'], ['a  b'])
    """
    if not keep_lines:
        return textwrap.wrap(text, WRAP_CHARS) or [text]
    lines: list[str] = []
    for line in text.strip("\n").split("\n"):
        lines += textwrap.wrap(line, WRAP_CHARS) or [""]
    return lines


def ink_coverage(text: str, em_px: int = EM_PX, keep_lines: bool = False) -> np.ndarray:
    """(H, W) ink coverage in [0, 1] of ``text`` in its :func:`wrapped_lines`, centred, with a
    :data:`PADDING_EM` margin."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    lines = wrapped_lines(text, keep_lines)
    dpi = 72.0  # 1 point = 1 pixel: fontsize in points is the em in pixels
    fig = Figure(figsize=(1.0, 1.0), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    fig.patch.set_alpha(0.0)
    artist = fig.text(0.5, 0.5, "\n".join(lines), fontsize=em_px, family="DejaVu Sans", color="white",
                      ha="center", va="center", multialignment="center", linespacing=LINE_SPACING_EM)
    extent = artist.get_window_extent(canvas.get_renderer())
    pad = PADDING_EM * em_px
    width_px = int(math.ceil(extent.width + 2 * pad))
    height_px = int(math.ceil(max(extent.height, len(lines) * LINE_SPACING_EM * em_px) + 2 * pad))
    fig.set_size_inches(width_px / dpi, height_px / dpi)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba(), dtype=np.float64)
    return rgba[:, :, 3] / 255.0


def text_image(text: str, em_px: int = EM_PX, ink_rgb: Colour = INK_RGB, panel_rgb: Colour = PANEL_RGB,
               keep_lines: bool = False) -> TextImage:
    """``text`` as ink over a panel, ``em_px`` texels per em (one rasterisation; :class:`TextImages` caches);
    ``keep_lines``: its line breaks kept (:func:`wrapped_lines`)."""
    if not text.strip():
        raise ValueError("text to draw must not be empty")
    alpha = ink_coverage(text, em_px, keep_lines)[:, :, None]
    pixels = np.asarray(panel_rgb, dtype=np.float64) * (1.0 - alpha) + np.asarray(ink_rgb, dtype=np.float64) * alpha
    lines_key = "|lines" if keep_lines else ""  # the prompt's key (and texture) as before
    digest = hashlib.sha256(f"{text}|{em_px}|{ink_rgb}|{panel_rgb}{lines_key}".encode()).hexdigest()[:16]
    return TextImage(text, ImageTexture(pixels, key=f"text:{digest}"), float((alpha > 0).mean()), int(em_px))


class TextImages:
    """Rasterised strings of one session: each string is rasterised once and the same immutable
    texture handed out every frame (so the renderer keeps it uploaded). ``rasterisations`` counts them."""

    def __init__(self, em_px: int = EM_PX) -> None:
        self.em_px = int(em_px)
        self._images: dict[tuple[str, bool], TextImage] = {}
        self.rasterisations = 0

    def image(self, text: str, keep_lines: bool = False) -> TextImage:
        cached = self._images.get((text, keep_lines))
        if cached is None:
            cached = self._images[(text, keep_lines)] = text_image(text, self.em_px, keep_lines=keep_lines)
            self.rasterisations += 1
        return cached
