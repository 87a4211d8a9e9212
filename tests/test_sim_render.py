"""Headless frames from the fixed camera (EGL), caption strip, PNG and MP4 files; the two CLI commands."""
import json

import imageio.v2 as imageio
import numpy as np
import pytest

from tasks.cli import main
from sim.config import DEFAULT_CONFIG
from sim.env import ArmSim
from sim.joystick import JoystickState, Mode
from sim.render import (ELLIPSIS, MARGIN, VideoWriter, _canvas, _text_width, caption_strip, describe, fit,
                        legend_strip, site_colour, write_png)


@pytest.fixture(scope="module")
def sim():
    arm = ArmSim()
    yield arm
    arm.close()


def coloured_pixels(frame: np.ndarray, rgb: tuple[int, int, int], tolerance: int = 60) -> int:
    return int((np.abs(frame.astype(int) - np.array(rgb)).max(axis=2) < tolerance).sum())


def test_frame_shows_the_cubes_and_follows_them(sim):
    sim.reset()
    frame = sim.render()
    height, width = sim.config.render.height, sim.config.render.width
    assert frame.shape == (height, width, 3) and frame.dtype == np.uint8
    red, blue = (217, 51, 38), (38, 89, 217)  # the cube colours, lit
    assert coloured_pixels(frame, red) > 100 and coloured_pixels(frame, blue) > 100
    sim.reset(cube_positions=[(5.0, 5.0), (-0.14, -0.45)])  # red cube far off the table, out of view
    assert coloured_pixels(sim.render(), red) < 10
    sim.reset()


def test_caption_strip_is_on_top_and_carries_the_text(sim):
    state = JoystickState({"F": 0.5}, frozenset({"B1"}))
    text = describe(Mode.WRIST, state)
    assert text.startswith("mode: wrist") and "F=0.50" in text and "B1" in text
    frame = sim.render(text)
    height = caption_strip((text,), frame.shape[1]).shape[0]
    assert frame.shape[0] == sim.config.render.height + height and height % 16 == 0
    strip = frame[:height]
    assert (strip.max(axis=2) > 200).sum() > 50  # white text drawn
    assert not np.array_equal(strip, caption_strip((describe(Mode.FINGERS, state),), frame.shape[1]))


def test_a_long_caption_line_is_shortened_to_the_frame_width_never_cut():
    width = 640
    long = "  24.8 s  film 8x  mode: translation  command: F=0.50 (move y-) L=0.20 (move x+)  | carry cube 1: descend"
    _, canvas = _canvas(width, 32)
    shown = fit(long, width - 2 * MARGIN, canvas)
    assert shown.endswith(ELLIPSIS) and long.startswith(shown[:-len(ELLIPSIS)])
    assert _text_width(shown, canvas) <= width - 2 * MARGIN < _text_width(long, canvas)
    assert fit("mode: wrist", width, canvas) == "mode: wrist"
    strip = caption_strip((long, "second line"), width)
    assert strip.shape == (48, width, 3)
    assert (strip[:, -MARGIN + 1:].max(axis=2) > 120).sum() == 0  # nothing drawn in the right margin
    assert (strip[:, width // 2:].max(axis=2) > 200).sum() > 50  # but the line does reach far right


def test_the_legend_shows_each_marker_in_its_colour(sim):
    colours = {site: site_colour(sim.model, site, "table") for site in ("location_a", "location_b")}
    assert colours["location_a"] != colours["location_b"]
    strip = legend_strip((("A: start", colours["location_a"]), ("B: target", colours["location_b"])), 640)
    for colour in colours.values():
        rgb = np.round(255 * np.array(colour))
        assert (np.abs(strip.astype(int) - rgb).max(axis=2) <= 3).sum() > 40
    frame = sim.render(("a caption",), legend=(("A: start", colours["location_a"]),))
    assert frame.shape[0] == 32 + sim.config.render.height + 32


def test_png_and_mp4_round_trip(sim, tmp_path):
    frames = []
    with VideoWriter(tmp_path / "clip.mp4", fps=30) as video:
        for _ in range(12):
            sim.step(JoystickState({"L": 1.0}))
            frames.append(sim.render("moving"))
            video.append(frames[-1])
    write_png(tmp_path / "last.png", frames[-1])
    np.testing.assert_array_equal(imageio.imread(tmp_path / "last.png"), frames[-1])
    decoded = [frame for frame in imageio.get_reader(tmp_path / "clip.mp4")]
    assert len(decoded) == 12 and decoded[0].shape == frames[0].shape
    assert np.abs(decoded[-1].astype(int) - frames[-1]).mean() < 8  # lossy, but the same picture
    assert not np.array_equal(frames[0], frames[-1])  # the arm moved


@pytest.mark.long
def test_cli_render_writes_mp4_and_png(tmp_path, capsys):
    """The command's whole path (its scripted run, every frame filmed, the last one as PNG) on frames of a
    sixth of the shipped size (--config): what is checked does not depend on the size, and the software
    renderer's and the encoder's work, most of the command's, shrinks with it (the shipped size is what
    the other tests here render)."""
    config, films = tmp_path / "config" / "sim.toml", tmp_path / "films"
    config.parent.mkdir()
    films.mkdir()
    shipped = DEFAULT_CONFIG.read_text()
    assert "width = 640\nheight = 480\n" in shipped
    config.write_text(shipped.replace("width = 640\nheight = 480\n", "width = 256\nheight = 192\n"))
    out, png = films / "run.mp4", films / "run.png"
    assert main(["render", "--config", str(config), "--out", str(out), "--png", str(png)]) == 0
    assert "mode switches 5, button presses 5" in capsys.readouterr().out
    assert imageio.get_reader(out).count_frames() > 100
    assert imageio.imread(png).shape[1:] == (256, 3)   # (the caption strip above the scene adds rows)
    assert sorted(p.name for p in films.iterdir()) == ["run.mp4", "run.png"]  # no leftovers


def test_cli_render_refuses_non_mp4_and_missing_directory(tmp_path, capsys):
    assert main(["render", "--out", str(tmp_path / "run.avi")]) == 2
    assert main(["render", "--out", str(tmp_path / "nowhere" / "run.mp4")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all(line.startswith("bomi: error: ") for line in err)


def test_cli_sim_check_prints_every_direction(tmp_path, capsys):
    record = tmp_path / "check.json"
    assert main(["sim-check", "--deflection", "0.5", "--json", str(record)]) == 0
    header, rule, *rows = capsys.readouterr().out.splitlines()
    assert len(rows) == 6 + 6 + 2 and set(rule) == {"-"}
    # the unit comes before the numbers and the tracking error; every row has a verdict (0.1 m/s: all reached)
    assert header.split()[:3] == ["mode", "function", "unit"] and header.index("unit") < header.index("tracking")
    assert [row.split()[2] for row in rows] == ["m/s"] * 6 + ["rad/s"] * 6 + ["1/s"] * 2
    assert all(row.endswith("  ok") for row in rows)
    results = json.loads(record.read_text())
    translation = [r for r in results if r["mode"] == "translation"]
    assert [r["function"] for r in translation] == ["F", "B", "R", "L", "Rr", "Lr"]
    assert all(abs(r["ratio"] - 1) < 0.05 for r in translation)  # 0.1 m/s is within every joint limit
