"""Texture synthesis (white and 1/f noise) and packing into one RGB texture array.

Each texture occupies one layer of an L x L array (L = the largest texture); its used size
is stored per primitive and texels are fetched nearest-neighbour in the shader, so textures of
different sizes share one array without resampling.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from psyop.errors import UserError
from psyop.rendering.scene import ImageTexture, NoiseKind, NoiseTexture


def decode_image_rgb(path: Path) -> np.ndarray:
    """An image file as (H, W, 3) float64 RGB in [0, 1] (8-bit files scaled, grey expanded)."""
    try:
        import matplotlib.image as mpimg

        pixels = np.asarray(mpimg.imread(path), dtype=np.float64)
    except Exception as error:  # noqa: BLE001 - a bad file raises OSError, ValueError, SyntaxError (PNG), ...
        raise UserError(f"cannot read image {path}: {error}") from None
    if pixels.max() > 1.0:
        pixels = pixels / 255.0
    if pixels.ndim == 2:
        pixels = np.repeat(pixels[:, :, None], 3, axis=2)
    return pixels[:, :, :3]


class ImageFiles:
    """Image-surface textures of one session, decoded once and reused every frame.

    Decoding a 1024 x 1024 PNG took 41.5 ms, and a scene is built every frame for each eye;
    here each file is decoded once per content (keyed by path, size and modification time,
    so an edited file is read again) and the same immutable :class:`ImageTexture` is handed
    out, which also lets the renderer keep the uploaded texture.
    """

    def __init__(self, base_dir: Path | None = None) -> None:
        self.base_dir = Path(base_dir) if base_dir is not None else Path(".")
        self._textures: dict[tuple[str, int, int, float], ImageTexture] = {}
        self.decodes = 0

    def texture(self, relative_path: str | Path, repeats: float = 1.0) -> ImageTexture:
        path = self.base_dir / relative_path
        try:
            stat = path.stat()
        except OSError as error:
            raise UserError(f"cannot read image {path}: {error.strerror or error}") from None
        key = (str(path), stat.st_size, stat.st_mtime_ns, float(repeats))
        cached = self._textures.get(key)
        if cached is None:
            cached = ImageTexture(decode_image_rgb(path), key=str(path), repeats=repeats)
            self.decodes += 1
            self._textures = {k: v for k, v in self._textures.items() if k[0] != key[0] or k[3] != key[3]}
            self._textures[key] = cached
        return cached


def noise_pixels(tex: NoiseTexture) -> np.ndarray:
    """(size, size, 3) float32 grey noise with the requested mean and RMS contrast (clipped to [0, 1])."""
    rng = np.random.default_rng(tex.seed)
    n = int(tex.size_px)
    white = rng.standard_normal((n, n))
    if tex.kind is NoiseKind.PINK:
        fy = np.fft.fftfreq(n)[:, None]
        fx = np.fft.fftfreq(n)[None, :]
        f = np.hypot(fx, fy)
        f[0, 0] = np.inf  # drop the DC term
        spectrum = np.fft.fft2(white) / np.where(np.isinf(f), np.inf, f)
        field = np.real(np.fft.ifft2(spectrum))
    else:
        field = white
    field = (field - field.mean()) / max(float(field.std()), 1e-12)
    grey = np.clip(tex.mean + tex.contrast * tex.mean * field, 0.0, 1.0)
    rgb = grey[:, :, None] * np.asarray(tex.tint, dtype=np.float64)[None, None, :]
    return rgb.astype(np.float32)


def texture_pixels(tex: NoiseTexture | ImageTexture) -> np.ndarray:
    """The RGB pixels of a texture material, top row first."""
    if isinstance(tex, ImageTexture):
        return np.asarray(tex.pixels, dtype=np.float32)
    return noise_pixels(tex)


def pack_layers(images: list[np.ndarray]) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Pack RGB images into a (layers, L, L, 4) float32 array (L = the largest side, at least 1).

    Returns the array and each image's (width, height) in texels. Images larger than 1024 texels
    on a side are decimated by striding (keeps the CI cheap; the studies use small textures).
    """
    shrunk = []
    for img in images:
        step = max(1, int(np.ceil(max(img.shape[:2]) / 1024)))
        shrunk.append(img[::step, ::step])
    side = max([1] + [max(i.shape[:2]) for i in shrunk])
    out = np.zeros((max(1, len(shrunk)), side, side, 4), dtype=np.float32)
    sizes = []
    for k, img in enumerate(shrunk):
        h, w = img.shape[:2]
        out[k, :h, :w, :3] = img
        out[k, :h, :w, 3] = 1.0
        sizes.append((w, h))
    return out, sizes
