"""Bad model files and configs: one-line SimError (model files) or BomiError (the config, read by
bomi.config_files) naming the file; the CLI exits 2 and writes nothing."""
import shutil
from pathlib import Path

import pytest

from bomi.errors import BomiError
from tasks.cli import main
from sim.config import DEFAULT_CONFIG, MODELS_DIR, load_config
from sim.env import ArmSim
from sim.errors import SimError
from sim.scene import build_scene


@pytest.fixture
def models(tmp_path) -> Path:
    target = tmp_path / "models"
    shutil.copytree(MODELS_DIR, target)
    return target


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def test_default_config_loads_with_the_measured_timing():
    config = load_config()
    assert config.physics.timestep == pytest.approx(1 / 480)
    assert config.control.full_speed == pytest.approx(0.20)


@pytest.mark.parametrize("old, new, complaint", [
    ("substeps = 8", 'substeps = "8"', "[physics] substeps: expected an integer, got '8'"),
    ("substeps = 8", "substeps = 2.5", "[physics] substeps: expected an integer"),
    ("full_speed = 0.20", "full_speed = -0.2", "[control] full_speed: must be > 0"),
    ("x = [-0.45, 0.45]", "x = [0.45, -0.45]", "[workspace] x: lower bound"),
    ("base_pos = [0.0, 0.0, 0.0]", "base_pos = [0.0, 0.0]", "[arm] base_pos: expected 3 values"),
    ("fps = 30", "fps = 30\nspeed = 2", "[render] unknown key(s) ['speed']"),
    ("[render]", "[rendering]", "[render] section missing"),
    ("fps = 30", "fps = 30\n[extra]\nx = 1", "unknown key(s) ['extra']"),
    ("control_hz = 60.0", "control_hz = nan", "[physics] control_hz: nan is not a finite number within +-1e+06"),
    ("[physics]", "[physics", "not valid TOML"),
    ("control_hz = 60.0", "control_hz = 1e300", "[physics] control_hz: 1e+300 is not a finite number within"),
    ("control_hz = 60.0", "control_hz = 1e5", "[physics] control_hz: must be at most 1000.0"),
    ("substeps = 8", "substeps = 1000000", "[physics] substeps: must be at most 100"),
    ("orientation_gain = 4.0", "orientation_gain = 1e5", "[control] orientation_gain: 100000.0 per s exceeds"),
    ("finger_gain = 10.0", "finger_gain = 61.0", "[control] finger_gain: 61.0 per s exceeds [physics] control_hz (60.0)"),
])
def test_bad_config_names_file_and_problem(tmp_path, old, new, complaint):
    path = tmp_path / "sim.toml"
    shutil.copy(DEFAULT_CONFIG, path)
    edit(path, old, new)
    with pytest.raises(BomiError) as info:
        load_config(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and complaint in message and "\n" not in message


def test_missing_config_file(tmp_path):
    with pytest.raises(BomiError, match="nope.toml: no such simulation config file"):
        load_config(tmp_path / "nope.toml")


@pytest.mark.parametrize("file, old, new, complaint", [
    ("scene.xml", "</mujoco>", "", "malformed model file"),
    ("scene.xml", 'camera name="workspace"', 'camera name="elsewhere"', "no camera named 'workspace'"),
    ("scene.xml", 'geom name="table"', 'geom name="desk"', "no geom named 'table'"),
    ("scene.xml", 'material="floor"/>', 'material="missing"/>', "model does not compile"),
    ("cube.xml", 'type="box"', 'type="boxx"', "malformed model file"),
    ("cube.xml", 'size="0.025 0.025 0.025"', 'size="0.025 0.025 -0.025"', "3 positive half-sizes"),
    ("cube.xml", 'mass="0.075"', 'mass="-1"', "model does not compile"),
])
def test_malformed_model_file_names_that_file(models, file, old, new, complaint):
    edit(models / file, old, new)
    with pytest.raises(SimError) as info:
        build_scene(load_config(), models)
    message = str(info.value)
    assert message.startswith(f"{models / file}: ") and complaint in message and "\n" not in message


def test_binary_garbage_model_file(models):
    (models / "cube.xml").write_bytes(b"\x00\xff garbage \x89PNG")
    with pytest.raises(SimError, match="cube.xml: malformed model file"):
        build_scene(load_config(), models)


def test_cli_reports_one_line_and_overwrites_nothing(models, tmp_path, capsys):
    edit(models / "scene.xml", "</mujoco>", "")
    out = tmp_path / "run.mp4"
    out.write_bytes(b"previous video")
    assert main(["render", "--models", str(models), "--out", str(out), "--force"]) == 2  # even when allowed to
    err = capsys.readouterr().err
    assert err.startswith("bomi: error: ") and err.count("\n") == 1 and "scene.xml" in err
    assert out.read_bytes() == b"previous video"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["models", "run.mp4"]


def test_cli_rejects_bad_config_for_sim_check(tmp_path, capsys):
    path = tmp_path / "sim.toml"
    path.write_text("[physics]\ncontrol_hz = 60.0\n")
    assert main(["sim-check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(path) in err and "[physics] substeps: missing" in err


@pytest.mark.parametrize("home, complaint", [
    ("[0.0, -1.5, 0.22]", "no joint solution"),       # beyond the arm's reach
    ("[0.0, -0.42, 0.005]", "outside the [workspace]"),  # the hand would be in the table
])
def test_unusable_home_pose_is_a_config_error(tmp_path, home, complaint):
    path = tmp_path / "sim.toml"
    shutil.copy(DEFAULT_CONFIG, path)
    edit(path, "home_tool_pos = [0.0, -0.42, 0.22]", f"home_tool_pos = {home}")
    with pytest.raises(SimError) as info:
        ArmSim(load_config(path))
    assert str(info.value).startswith(f"{path}: [arm] home_tool_pos") and complaint in str(info.value)


def test_a_frame_larger_than_the_offscreen_framebuffer_is_refused_before_any_work(tmp_path):
    path = tmp_path / "sim.toml"
    shutil.copy(DEFAULT_CONFIG, path)
    edit(path, "width = 640", "width = 4000")
    with pytest.raises(SimError) as info:
        ArmSim(load_config(path))
    assert str(info.value) == (f"{path}: [render] width: 4000 px exceeds the scene's offscreen framebuffer "
                               "(1280 px, <global offwidth> in the scene's MJCF)")
    edit(path, "width = 4000", "width = 1280")
    ArmSim(load_config(path)).close()  # the framebuffer's own size fits
