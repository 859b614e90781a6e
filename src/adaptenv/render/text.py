"""Fonts and text for the renders: measuring (label placement needs sizes) and drawing (cached masks)."""

from __future__ import annotations

from functools import lru_cache

from PIL import Image, ImageDraw, ImageFont

RGB = tuple[int, int, int]


@lru_cache(maxsize=64)
def get_font(size: int, bold: bool = False) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """A TrueType font of this pixel size: DejaVu Sans Condensed when installed, else Pillow's own."""
    name = "DejaVuSansCondensed-Bold.ttf" if bold else "DejaVuSansCondensed.ttf"
    try:
        return ImageFont.truetype(name, size)
    except OSError:
        return ImageFont.load_default(size=size)


@lru_cache(maxsize=8192)
def text_size(text: str, size: int, bold: bool = False) -> tuple[float, float]:
    """Width and line height (px) of ``text`` drawn with :func:`get_font`."""
    font = get_font(size, bold)
    ascent, descent = font.getmetrics() if hasattr(font, "getmetrics") else (size, 0)
    return float(font.getlength(text)), float(ascent + descent)


@lru_cache(maxsize=4096)
def _text_mask(text: str, size: int, bold: bool, anchor: str) -> tuple[Image.Image, int, int]:
    """The anti-aliased coverage of a text as an "L" image plus its offset from the anchor point.

    Cached: a house is re-rendered after every edit with the same ids, so each label is
    rasterized once.
    """
    font = get_font(size, bold)
    left, top, right, bottom = font.getbbox(text, anchor=anchor)
    mask = Image.new("L", (max(1, right - left), max(1, bottom - top)), 0)
    ImageDraw.Draw(mask).text((-left, -top), text, font=font, fill=255, anchor=anchor)
    return mask, left, top


def draw_text(image: Image.Image, xy: tuple[float, float], text: str, size: int, fill: RGB,
              anchor: str = "la", bold: bool = False) -> None:
    """Like ``ImageDraw.text`` with :func:`get_font`, through a cache of rasterized texts."""
    mask, left, top = _text_mask(text, size, bold, anchor)
    image.paste(fill, (int(round(xy[0])) + left, int(round(xy[1])) + top), mask)
