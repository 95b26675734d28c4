"""Text for the participant: a string rasterised once to an RGB image, drawn as a textured quad.

psyop's renderer draws analytic primitives only; a line of text (the response phase's prompt,
docs/protocols.md) becomes an :class:`ImageTexture` of light ink on a dark panel, rasterised by
matplotlib's Agg canvas (already a dependency; the bundled DejaVu Sans font) and cached per string
for the session (:class:`TextImages`), like image surfaces (psyop.rendering.textures.ImageFiles).

Legibility (docs/rendering.md, "Legible text"): on a display of given views (:class:`EyeView`: each eye's pixels,
field of view and where the panel's centre lies), :func:`layout_text` sizes one em to at least :data:`MIN_EM_DEG`
and to a capital letter of at least :data:`MIN_CAP_HEIGHT_PX` device pixels (growing as the pixels per degree
shrink), wraps the lines so the panel stays inside every eye's view, and raises :class:`TextDoesNotFit` when even
that cannot fit.
"""

from __future__ import annotations

import hashlib
import math
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from psyop.optics.display import DisplayProfile
from psyop.rendering.scene import Colour, ImageTexture

#: Texels per em (the font size) of a rasterised string when no display is given. A session rasterises at
#: its display's central pixel density (:func:`em_px_for_display`): the texture is fetched nearest-neighbour,
#: and one texel per pixel keeps the glyphs' strokes (a finer texture drops some when minified).
EM_PX = 32
MIN_EM_PX = 8
#: Strings are wrapped at this many characters per line (on spaces), fewer where a line would leave the view.
WRAP_CHARS = 40
#: The fewest characters per line a wrap may come down to before the text is refused as too wide.
MIN_WRAP_CHARS = 8
#: DejaVu Sans's capital height in em: its 'H' is 1493 of the font's 2048 units per em.
CAP_HEIGHT_EM = 1493 / 2048
#: A capital letter is at least this many device pixels tall on every display.
MIN_CAP_HEIGHT_PX = 12
#: The layout aims one pixel above :data:`MIN_CAP_HEIGHT_PX`: a glyph's anti-aliased top and bottom rows are partly
#: covered, so its measured height is up to a pixel less than its outline's.
CAP_HEIGHT_AIM_PX = MIN_CAP_HEIGHT_PX + 1
#: One em (the font size) subtends at least this angle: 1 deg (a capital 0.73 deg, well above acuity limits).
MIN_EM_DEG = 1.0
#: The panel keeps this share of each view's width and height clear at each edge (a headset's lens edge blurs).
VIEW_MARGIN_SHARE = 0.05
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
    #: the angle one em subtends where it is drawn (psyop.stimulus.text_scene sizes the panel by it)
    em_deg: float = MIN_EM_DEG

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


def wrapped_lines(text: str, keep_lines: bool = False, wrap_chars: int = WRAP_CHARS) -> list[str]:
    r"""The lines ``text`` is drawn in: wrapped at ``wrap_chars`` on spaces; ``keep_lines``: each of its own
    lines wrapped separately (an empty line kept), as a session screen's page is written (psyop.session.screens),
    else its line breaks are spaces (the response prompt).

    Examples
    --------
    >>> wrapped_lines("a\n\nb", keep_lines=True), wrapped_lines("a\n\nb")
    (['a', '', 'b'], ['a  b'])
    """
    if not keep_lines:
        return textwrap.wrap(text, wrap_chars) or [text]
    lines: list[str] = []
    for line in text.strip("\n").split("\n"):
        lines += textwrap.wrap(line, wrap_chars) or [""]
    return lines


@dataclass(frozen=True)
class EyeView:
    """One eye's image where text is drawn: its size in device pixels, its (left, right, bottom, top) tangents
    from the centre of projection, and ``panel_x_tan``, the tangent of the text panel's centre (right positive:
    0 when the panel is straight ahead of the eye, the eye's offset over the panel's distance in stereo)."""

    width_px: int
    height_px: int
    tangents: tuple[float, float, float, float]
    panel_x_tan: float = 0.0

    @property
    def px_per_tan_y(self) -> float:
        return self.height_px / (self.tangents[3] - self.tangents[2])

    def room_tan(self) -> tuple[float, float]:
        """The widest and tallest panel (tangent units) centred where it is drawn that keeps the
        :data:`VIEW_MARGIN_SHARE` margins."""
        left, right, bottom, top = self.tangents
        mx, my = VIEW_MARGIN_SHARE * (right - left), VIEW_MARGIN_SHARE * (top - bottom)
        c = self.panel_x_tan
        return 2.0 * min(c - left - mx, right - mx - c), 2.0 * min(-bottom - my, top - my)


def display_views(display: DisplayProfile, panel_x_tan: dict[str, float]) -> tuple[EyeView, ...]:
    """The views of ``display``'s eyes (``panel_x_tan``: eye -> the panel centre's tangent in that eye)."""
    return tuple(EyeView(display.width_px, display.height_px, display.frustum_tangents(eye), float(x))
                 for eye, x in panel_x_tan.items())


@dataclass(frozen=True)
class TextLayout:
    """How a string is drawn on given views: ``em_px`` texels per em, one em subtending ``em_deg``, wrapped at
    ``wrap_chars`` into ``lines``."""

    em_px: int
    em_deg: float
    wrap_chars: int
    lines: tuple[str, ...]


class TextDoesNotFit(ValueError):
    """A text that cannot be drawn inside the view at the legible minimum (the message says why and what fits)."""


def legible_em(views: tuple[EyeView, ...]) -> tuple[int, float]:
    """(texels per em, degrees per em) on ``views``: one em of at least :data:`MIN_EM_DEG` and enough pixels for a
    capital of :data:`CAP_HEIGHT_AIM_PX` on the view with the fewest pixels per degree, one texel per pixel there."""
    density = min(view.px_per_tan_y for view in views)  # pixels per unit tangent at the image centre
    at_min_deg = int(round(density * 2.0 * math.tan(math.radians(MIN_EM_DEG) / 2.0)))
    em_px = max(MIN_EM_PX, at_min_deg, math.ceil(CAP_HEIGHT_AIM_PX / CAP_HEIGHT_EM))
    em_deg = max(MIN_EM_DEG, math.degrees(2.0 * math.atan(em_px / density / 2.0)))
    return em_px, em_deg


def line_width_em(line: str) -> float:
    """The advance width of ``line`` in DejaVu Sans, in em (the width :func:`ink_coverage` draws it at)."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextToPath

    size = 100.0
    width, _, _ = TextToPath().get_text_width_height_descent(line, FontProperties(family="DejaVu Sans", size=size),
                                                             ismath=False)
    return float(width) / size


def layout_text(text: str, keep_lines: bool, views: tuple[EyeView, ...]) -> TextLayout:
    """``text`` laid out legibly on ``views`` (:func:`legible_em`), wrapped at the most characters per line (at most
    :data:`WRAP_CHARS`) that keep its panel inside every view; :class:`TextDoesNotFit` when no wrap does, or when
    its lines are more than fit in height."""
    em_px, em_deg = legible_em(views)
    em_tan = 2.0 * math.tan(math.radians(em_deg) / 2.0)
    room_w, room_h = (min(r) for r in zip(*(view.room_tan() for view in views)))
    max_w_em, max_h_em = room_w / em_tan, room_h / em_tan
    slack_em = 2.0 / em_px  # the rasterised panel's size is rounded up to whole texels
    size = f"one em {em_deg:.2f} deg ({em_px} px, capitals {CAP_HEIGHT_EM * em_px:.1f} px)"
    for wrap in range(WRAP_CHARS, MIN_WRAP_CHARS - 1, -1):
        lines = wrapped_lines(text, keep_lines, wrap)
        if max(line_width_em(line) for line in lines) + 2 * PADDING_EM + slack_em <= max_w_em:
            break
    else:
        raise TextDoesNotFit(f"the text does not fit the view's width even at {MIN_WRAP_CHARS} characters a line "
                             f"with {size}; shorten its longest word")
    height_em = len(lines) * LINE_SPACING_EM + 2 * PADDING_EM + slack_em
    if height_em > max_h_em:
        fit = max(0, int((max_h_em - 2 * PADDING_EM - slack_em) / LINE_SPACING_EM))
        raise TextDoesNotFit(f"the text takes {len(lines)} lines of at most {wrap} characters with {size}, more "
                             f"than the {fit} that fit in view; shorten it or split it into pages, or show the "
                             "session larger (a larger --window-scale)")
    return TextLayout(int(em_px), float(em_deg), int(wrap), tuple(lines))


def ink_coverage(text: str, em_px: int = EM_PX, keep_lines: bool = False, wrap_chars: int = WRAP_CHARS) -> np.ndarray:
    """(H, W) ink coverage in [0, 1] of ``text`` in its :func:`wrapped_lines`, centred, with a
    :data:`PADDING_EM` margin."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    lines = wrapped_lines(text, keep_lines, wrap_chars)
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
               keep_lines: bool = False, layout: TextLayout | None = None) -> TextImage:
    """``text`` as ink over a panel, ``em_px`` texels per em (one rasterisation; :class:`TextImages` caches);
    ``keep_lines``: its line breaks kept (:func:`wrapped_lines`); ``layout``: its em and wrap on a display
    (:func:`layout_text`; it then sets ``em_px``)."""
    if not text.strip():
        raise ValueError("text to draw must not be empty")
    wrap, em_deg = WRAP_CHARS, MIN_EM_DEG
    if layout is not None:
        em_px, wrap, em_deg = layout.em_px, layout.wrap_chars, layout.em_deg
    alpha = ink_coverage(text, em_px, keep_lines, wrap)[:, :, None]
    pixels = np.asarray(panel_rgb, dtype=np.float64) * (1.0 - alpha) + np.asarray(ink_rgb, dtype=np.float64) * alpha
    lines_key = "|lines" if keep_lines else ""  # the prompt's key (and texture) as before
    wrap_key = "" if wrap == WRAP_CHARS else f"|wrap{wrap}"
    digest = hashlib.sha256(f"{text}|{em_px}|{ink_rgb}|{panel_rgb}{lines_key}{wrap_key}".encode()).hexdigest()[:16]
    return TextImage(text, ImageTexture(pixels, key=f"text:{digest}"), float((alpha > 0).mean()), int(em_px),
                     float(em_deg))


class TextImages:
    """Rasterised strings of one session: each string is rasterised once and the same immutable
    texture handed out every frame (so the renderer keeps it uploaded). ``rasterisations`` counts them.
    ``views``: the display's eye views; each string is then laid out legibly on them (:func:`layout_text`,
    which raises :class:`TextDoesNotFit`); without views, ``em_px`` texels per em and 1 deg letters."""

    def __init__(self, em_px: int = EM_PX, views: tuple[EyeView, ...] | None = None) -> None:
        self.em_px = int(em_px) if not views else legible_em(views)[0]
        self.views = views
        self._images: dict[tuple[str, bool], TextImage] = {}
        self.rasterisations = 0

    def layout(self, text: str, keep_lines: bool = False) -> TextLayout | None:
        """How ``text`` is laid out on the views (None without views)."""
        return None if not self.views else layout_text(text, keep_lines, self.views)

    def page(self, text: str, picture: Picture) -> TextImage:
        """``text`` (line breaks kept) under ``picture`` on one panel (:func:`picture_page`), each page once."""
        key = (f"{text}\0{picture.path}\0{picture.width_deg}", True)
        cached = self._images.get(key)
        if cached is None:
            cached = self._images[key] = picture_page(self.image(text, keep_lines=True), picture, self.views)
            self.rasterisations += 1
        return cached

    def image(self, text: str, keep_lines: bool = False) -> TextImage:
        cached = self._images.get((text, keep_lines))
        if cached is None:
            cached = self._images[(text, keep_lines)] = text_image(text, self.em_px, keep_lines=keep_lines,
                                                                   layout=self.layout(text, keep_lines))
            self.rasterisations += 1
        return cached


#: a picture's width when no view limits it (text drawn without a display): the width, in deg, it is drawn at
PICTURE_WIDTH_DEG_WITHOUT_VIEWS = 20.0


@dataclass(frozen=True)
class Picture:
    """An image drawn above a page's text (``session: instructions: pages: image:``): the decoded file ``path`` and
    its angular width (None: as wide as the view leaves room for, :func:`picture_size_px`)."""

    path: str
    width_deg: float | None = None


def picture_size_px(shape_hw: tuple[int, int], text: TextImage, width_deg: float | None,
                    views: tuple[EyeView, ...] | None) -> tuple[int, int]:
    """(width, height) in texels of a picture of ``shape_hw`` pixels drawn above ``text``'s panel: ``width_deg``
    wide (the panel's texels are ``text.em_px`` per em of ``text.em_deg``, so w = em_px tan(width/2) / tan(em/2)),
    or, without a width, the largest that keeps the page inside every view (:meth:`EyeView.room_tan`). Raises
    :class:`TextDoesNotFit` when the picture at ``width_deg`` with the text below it leaves the view."""
    height, width = shape_hw
    texel_tan = 2.0 * math.tan(math.radians(text.em_deg) / 2.0) / text.em_px
    pad_px = PADDING_EM * text.em_px
    if views:
        room_w, room_h = (min(r) for r in zip(*(view.room_tan() for view in views)))
        max_w, max_h = room_w / texel_tan - 2 * pad_px - 2, room_h / texel_tan - text.texture.pixels.shape[0] - 2
    else:
        max_w = max_h = math.inf
    if width_deg is None:
        scale = min(max_w / width, max_h / height) if views else \
            2.0 * math.tan(math.radians(PICTURE_WIDTH_DEG_WITHOUT_VIEWS) / 2.0) / texel_tan / width
    else:
        scale = 2.0 * math.tan(math.radians(width_deg) / 2.0) / texel_tan / width
    w_px, h_px = max(1, int(round(width * scale))), max(1, int(round(height * scale)))
    if w_px > max_w + 1e-6 or h_px > max_h + 1e-6:
        fit_deg = 2.0 * math.degrees(math.atan(min(max_w, max_h * width / height) * texel_tan / 2.0))
        wide = "as wide as fits" if width_deg is None else f"{width_deg:g} deg wide"
        raise TextDoesNotFit(f"the image {wide} ({w_px} x {h_px} texels) does not fit the view "
                             f"above its text; give image_width_deg {fit_deg:.1f} or less, or shorten the text")
    return w_px, h_px


def picture_page(text: TextImage, picture: Picture, views: tuple[EyeView, ...] | None) -> TextImage:
    """One panel: ``picture`` (decoded, resized with Pillow's area filter to :func:`picture_size_px`) centred at the
    top, a :data:`PADDING_EM` margin above it, and ``text``'s panel centred below it, on the panel colour."""
    from PIL import Image

    from psyop.rendering.textures import decode_image_rgb

    rgb = decode_image_rgb(Path(picture.path))
    w_px, h_px = picture_size_px(rgb.shape[:2], text, picture.width_deg, views)
    resized = Image.fromarray(np.round(rgb * 255.0).astype(np.uint8)).resize((w_px, h_px), Image.Resampling.BOX)
    pad = int(round(PADDING_EM * text.em_px))
    below = text.texture.pixels
    width = max(below.shape[1], w_px + 2 * pad)
    pixels = np.empty((pad + h_px + below.shape[0], width, 3))
    pixels[:] = np.asarray(PANEL_RGB, dtype=np.float64)
    x0 = (width - w_px) // 2
    pixels[pad:pad + h_px, x0:x0 + w_px] = np.asarray(resized, dtype=np.float64) / 255.0
    xt = (width - below.shape[1]) // 2
    pixels[pad + h_px:, xt:xt + below.shape[1]] = below
    digest = hashlib.sha256(f"{text.texture.key}|{picture.path}|{w_px}x{h_px}".encode()).hexdigest()[:16]
    return TextImage(text.text, ImageTexture(pixels, key=f"page:{digest}"), text.ink_fraction, text.em_px, text.em_deg)
