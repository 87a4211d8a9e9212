"""`bomi live`'s viewer in a real window, as a person would see it: an X server (Xvfb), the
emulator streaming the virtual P1 over a pty, `bomi live` with its MuJoCo viewer (and --video), a
screenshot of the screen a few seconds in, then the run ends by itself and must shut down cleanly.

The viewer is the only window the project opens (figures are drawn with matplotlib's Agg backend,
films offscreen through EGL). Skipped only when Xvfb is not installed (Debian package xvfb, which
.ci/run installs).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import imageio.v2 as imageio
import imageio_ffmpeg
import numpy as np
import pytest

from tasks.trials.displays import FILM_NICENESS

XVFB = shutil.which("Xvfb")
pytestmark = [pytest.mark.real_time, pytest.mark.skipif(XVFB is None, reason="Xvfb is not installed (Debian package xvfb; .ci/run installs it)")]
SCREEN = (1280, 800)
# How long `bomi live` runs: its neutral is taken ~13 s in (the gate's 12 s warm-up floor, then 100
# samples), the screenshot 2 s later; the rest (~3.5 s measured) is margin for the screenshot and the
# threads' niceness to be read while the window is still open. The viewer and the film draw all the
# while: the test's processor time grows with this.
LIVE_S = 19.0


@pytest.fixture
def x_display():
    """A fresh Xvfb server; its display name (Xvfb picks a free number and writes it to a pipe)."""
    read_end, write_end = os.pipe()
    server = subprocess.Popen([XVFB, "-displayfd", str(write_end), "-screen", "0", f"{SCREEN[0]}x{SCREEN[1]}x24",
                               "-nolisten", "tcp"], pass_fds=(write_end,), stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    os.close(write_end)
    with os.fdopen(read_end) as numbers:
        number = numbers.readline().strip()
    assert number.isdigit(), "Xvfb did not start"
    yield f":{number}"
    server.terminate()
    server.wait(timeout=10)


def screenshot(display: str, path: Path) -> np.ndarray:
    """The whole screen as RGB, grabbed by the ffmpeg that imageio-ffmpeg ships (its x11grab device)."""
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "x11grab", "-video_size",
                    f"{SCREEN[0]}x{SCREEN[1]}", "-i", display, "-frames:v", "1", str(path)], check=True, timeout=30)
    return imageio.imread(path)[:, :, :3].astype(int)


def thread_niceness(pid: int) -> dict[int, tuple[str, int]]:
    """Each thread of a running process (Linux's /proc): its name and niceness (its stat's 19th field);
    a thread that ends while it is read is left out."""
    threads = {}
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            name, stat = (task / "comm").read_text().strip(), (task / "stat").read_text()
        except (FileNotFoundError, ProcessLookupError):
            continue
        threads[int(task.name)] = (name, int(stat.rsplit(")", 1)[1].split()[16]))
    return threads


def arm_pixels(image: np.ndarray) -> int:
    """Pixels in the JACO's colours: its near-black links are dark neutral grey (the floor's dark
    checkers are bluish, the sky and the screen around the window pure black)."""
    brightest, spread = image.max(axis=2), image.max(axis=2) - image.min(axis=2)
    return int(((brightest >= 5) & (brightest <= 35) & (spread <= 3)).sum())


def table_pixels(image: np.ndarray) -> int:
    """The lit table top: warm tan (red > green > blue, well apart)."""
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    return int(((r > 150) & (r > g) & (g > b) & (r - b > 60) & (r - b < 130)).sum())


def cube_pixels(image: np.ndarray, channel: int) -> int:
    """A saturated red (channel 0) or blue (channel 2) cube."""
    others = [k for k in range(3) if k != channel]
    return int(((image[..., channel] > 180) & (image[..., others].max(axis=-1) < 140)).sum())


def text_pixels(image: np.ndarray) -> int:
    """Near-white neutral pixels: the viewer's overlay text."""
    brightest, spread = image.max(axis=2), image.max(axis=2) - image.min(axis=2)
    return int(((brightest >= 200) & (spread <= 10)).sum())


def test_live_viewer_draws_the_arm_and_its_status_and_closes_cleanly(tmp_path, p1_model_file, x_display):
    env = os.environ | {"DISPLAY": x_display, "PYTHONPATH": os.pathsep.join(sys.path)}
    env.pop("WAYLAND_DISPLAY", None)
    emulator = subprocess.Popen(
        [sys.executable, "-m", "tasks.cli", "emulate", "--participant", "P1", "--to", "pty", "--loss", "0",
         "--hold", "2", "--neutral", "18", "--duration", "60", "--linger", "1"],   # still while the filter settles (12 s)
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    video = tmp_path / "live.mp4"
    try:
        port = emulator.stdout.readline().strip()
        assert port.startswith("/dev/pts/")
        live = subprocess.Popen(
            [sys.executable, "-m", "tasks.cli", "live", "--port", port, "--profile", "P1", "--model",
             str(p1_model_file), "--duration", f"{LIVE_S:g}", "--retries", "0", "--video", str(video)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        err: list[str] = []
        calibrated = threading.Event()

        def read_stderr() -> None:
            for line in live.stderr:
                err.append(line)
                if "live: neutral offsets" in line:
                    calibrated.set()

        reader = threading.Thread(target=read_stderr, daemon=True)
        reader.start()
        assert calibrated.wait(timeout=120), "".join(err)
        time.sleep(2.0)  # a few seconds of the arm driven by the stream
        shot = screenshot(x_display, tmp_path / "screen.png")
        niceness = thread_niceness(live.pid)
        out, _ = live.communicate(timeout=120)
        reader.join(timeout=10)
    finally:
        emulator.kill()
        emulator.wait(timeout=10)
    log = "".join(err)
    # closed cleanly: exit code 0, the run's summary printed, no X or GL error on the way out
    assert live.returncode == 0, log
    assert "live: " in out and " ticks, " in out and f"wrote {video}" in out
    assert "running headless" not in log and "X Error" not in log and "Traceback" not in log
    # the viewer's threads (its own and the software renderer's workers, llvmpipe-N) at the lowest
    # priority, the loop that drives the arm (the main thread) at its own
    renderers = [nice for (name, nice) in niceness.values() if name.startswith("llvmpipe")]
    assert renderers and set(renderers) == {FILM_NICENESS}, niceness
    assert niceness[live.pid][1] == os.getpriority(os.PRIO_PROCESS, 0), niceness
    # the window showed the scene: the table, both cubes, the arm, and the status text in its corner
    assert table_pixels(shot) > 20000, "table"
    assert cube_pixels(shot, 0) > 50 and cube_pixels(shot, 2) > 50, "cubes"
    assert arm_pixels(shot) > 2000, "arm"
    corner = shot[:300, :450]
    assert text_pixels(corner) > 300, "status text"
    assert text_pixels(shot[400:, 900:]) < 50  # (text only where the status is)
    # the film made alongside: the fixed camera with the status line as caption
    frames = imageio.mimread(video, memtest=False)
    # real time at 30 fps (frames repeat if rendering lags)
    assert 0.5 * LIVE_S * 30 < len(frames) <= 30 * (LIVE_S + 1), out
    assert arm_pixels(np.asarray(frames[-1])[:, :, :3].astype(int)) > 1000
    assert text_pixels(np.asarray(frames[-1])[:32].astype(int)) > 100


def test_pixel_checks_tell_an_empty_screen_from_the_scene():
    """The checks above could fail: an empty (black) screen or a uniform window passes none of them."""
    black = np.zeros((SCREEN[1], SCREEN[0], 3), dtype=int)
    grey = np.full_like(black, 60)
    for image in (black, grey):
        assert arm_pixels(image) == 0 and text_pixels(image) == 0 and table_pixels(image) == 0
        assert cube_pixels(image, 0) == 0 and cube_pixels(image, 2) == 0
