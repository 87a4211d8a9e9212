"""Headless frames from the fixed workspace camera, with a caption strip; PNG and MP4 output.

MuJoCo renders offscreen through EGL (``MUJOCO_GL=egl``, set in ``sim/__init__``); the caption
(mode and command) is drawn by matplotlib into a strip above the frame, cached per text since
it rarely changes. MP4 goes through imageio's ffmpeg plugin (imageio-ffmpeg ships the encoder).
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import imageio.v2 as imageio
import mujoco
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sim.errors import SimError
from sim.joystick import THREE_AXIS, JoystickState, Layout, Mode

CAPTION_HEIGHT = 32


@lru_cache(maxsize=256)
def caption_strip(text: str, width: int, height: int = CAPTION_HEIGHT) -> np.ndarray:
    """An RGB strip (height, width, 3) with ``text`` in white on dark grey."""
    dpi = 100
    figure = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=(0.12, 0.12, 0.14))
    canvas = FigureCanvasAgg(figure)
    figure.text(0.01, 0.5, text, color="white", fontsize=12, va="center", ha="left", family="monospace")
    canvas.draw()
    strip = np.asarray(canvas.buffer_rgba())[:, :, :3].copy()
    strip.setflags(write=False)
    return strip


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

    def render(self, data: mujoco.MjData, caption: str | None = None) -> np.ndarray:
        self.renderer.update_scene(data, camera=self.camera)
        frame = self.renderer.render()
        if caption is None:
            return frame
        return np.vstack((caption_strip(caption, self.width), frame))

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
