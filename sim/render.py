"""Headless frames from the fixed workspace camera, with a caption strip; PNG and MP4 output.

MuJoCo renders offscreen through EGL (``MUJOCO_GL=egl``, set in ``sim/__init__``); the caption
(mode and command, one or more lines) is drawn by matplotlib into a strip above the frame, each
line shortened to the frame's width as measured with the font, and cached per text since it
rarely changes; an optional legend strip below names the coloured markers. MP4 goes through
imageio's ffmpeg plugin (imageio-ffmpeg ships the encoder).
"""
from __future__ import annotations

import os
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path

import imageio.v2 as imageio
import mujoco
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.patches import Circle
from matplotlib.transforms import IdentityTransform

from sim.errors import SimError
from sim.joystick import THREE_AXIS, JoystickState, Layout, Mode

LINE_HEIGHT = 16  # pixels per caption line; strips are multiples of 16 px high (H.264 macro blocks)
MARGIN = 6  # pixels left and right of the text
DPI = 100
FONT = FontProperties(family="monospace", size=10)
BACKGROUND = (0.12, 0.12, 0.14)
ELLIPSIS = "..."
Legend = tuple[tuple[str, tuple[float, float, float]], ...]  # (label, RGB in 0..1) per marker


def _strip_height(lines: int) -> int:
    return 16 * -(-(lines * LINE_HEIGHT + 4) // 16)


def _text_width(text: str, canvas: FigureCanvasAgg) -> float:
    width, _, _ = canvas.get_renderer().get_text_width_height_descent(text, FONT, ismath=False)
    return width


def fit(text: str, width: float, canvas: FigureCanvasAgg) -> str:
    """``text`` if it fits in ``width`` pixels in the caption font, else its longest head that fits
    followed by an ellipsis."""
    if _text_width(text, canvas) <= width:
        return text
    low, high = 0, len(text)  # the longest head that fits with the ellipsis: binary search
    while low < high:
        middle = (low + high + 1) // 2
        if _text_width(text[:middle].rstrip() + ELLIPSIS, canvas) <= width:
            low = middle
        else:
            high = middle - 1
    return text[:low].rstrip() + ELLIPSIS


def _canvas(width: int, height: int) -> tuple[Figure, FigureCanvasAgg]:
    figure = Figure(figsize=(width / DPI, height / DPI), dpi=DPI, facecolor=BACKGROUND)
    return figure, FigureCanvasAgg(figure)


def _pixels(figure: Figure, canvas: FigureCanvasAgg) -> np.ndarray:
    canvas.draw()
    strip = np.asarray(canvas.buffer_rgba())[:, :, :3].copy()
    strip.setflags(write=False)
    return strip


@lru_cache(maxsize=512)
def caption_strip(lines: tuple[str, ...], width: int) -> np.ndarray:
    """An RGB strip (height, width, 3) with one text line per entry in white on dark grey, each
    shortened to fit the width; the height depends only on the number of lines."""
    height = _strip_height(len(lines))
    figure, canvas = _canvas(width, height)
    for k, line in enumerate(lines):
        y = 1 - (2 + (k + 0.5) * LINE_HEIGHT) / height
        figure.text(MARGIN / width, y, fit(line, width - 2 * MARGIN, canvas), color="white", va="center",
                    ha="left", fontproperties=FONT)
    return _pixels(figure, canvas)


@lru_cache(maxsize=8)
def legend_strip(entries: Legend, width: int) -> np.ndarray:
    """A one-line RGB strip: a disc in each marker's colour followed by its label."""
    height = _strip_height(1)
    figure, canvas = _canvas(width, height)
    x = MARGIN
    for label, colour in entries:
        figure.patches.append(Circle((x + 6, height / 2), 6, color=colour, transform=IdentityTransform()))
        figure.text((x + 16) / width, 0.5, label, color="white", va="center", ha="left", fontproperties=FONT)
        x += 16 + _text_width(label, canvas) + 24
    return _pixels(figure, canvas)


def site_colour(model: mujoco.MjModel, site: str, under: str) -> tuple[float, float, float]:
    """The colour a (translucent) site shows over geom ``under``: its material blended over the geom's."""
    top = model.mat_rgba[model.site_matid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, site)]]
    bottom = model.mat_rgba[model.geom_matid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, under)]]
    return tuple(float(v) for v in top[3] * top[:3] + (1 - top[3]) * bottom[:3])


def describe(mode: Mode, state: JoystickState, layout: Layout = THREE_AXIS) -> str:
    """Caption text: the mode, the functions held (with deflections and what they do in the mode of
    ``layout``) and buttons pressed."""
    effects = layout.effects[mode]
    held = " ".join(f"{name}={amount:.2f} ({effects[name].label if name in effects else 'nothing'})"
                    for name, amount in state.deflection.items() if amount > 0)
    pressed = " ".join(sorted(state.pressed))
    return f"mode: {mode.value:<11}  command: {held or 'none'}{'  pressed: ' + pressed if pressed else ''}"


class FrameRenderer:
    """Renders the scene from one fixed camera, optionally with a caption strip on top."""

    def __init__(self, model: mujoco.MjModel, camera: str, width: int, height: int):
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0:
            raise SimError(f"scene has no camera named {camera!r}")
        self.camera = camera
        self.width = width
        try:
            self.renderer = mujoco.Renderer(model, height=height, width=width)
        except mujoco.FatalError as exc:
            raise SimError(f"cannot open an offscreen OpenGL context ({exc}); MUJOCO_GL="
                           f"{os.environ.get('MUJOCO_GL', '')!r} must name a headless backend (egl, osmesa) "
                           "before mujoco is first imported") from None

    def render(self, data: mujoco.MjData, caption: str | Sequence[str] | None = None,
               legend: Legend = ()) -> np.ndarray:
        """The camera's view, with the caption's lines above it and the legend below (if given)."""
        self.renderer.update_scene(data, camera=self.camera)
        parts = [self.renderer.render()]
        if caption is not None:
            parts.insert(0, caption_strip((caption,) if isinstance(caption, str) else tuple(caption), self.width))
        if legend:
            parts.append(legend_strip(legend, self.width))
        return np.vstack(parts) if len(parts) > 1 else parts[0]

    def close(self) -> None:
        self.renderer.close()


def write_png(path: Path, frame: np.ndarray) -> None:
    imageio.imwrite(path, frame)


class VideoWriter:
    """An MP4 (H.264) file written frame by frame."""

    def __init__(self, path: Path, fps: float):
        self.path = Path(path)
        self.writer = imageio.get_writer(self.path, fps=fps, codec="libx264", macro_block_size=16,
                                         quality=7, pixelformat="yuv420p")

    def append(self, frame: np.ndarray) -> None:
        self.writer.append_data(frame)

    def close(self) -> None:
        self.writer.close()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
