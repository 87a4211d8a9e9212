"""The scene: dm_control's Kinova JACO arm and hand on the project's table with cubes and markers.

Each entity owns its MJCF fragment (composer style): the arena (``models/scene.xml``: table,
markers, camera, contact options), the cubes (``models/cube.xml``) and dm_control's ``JacoArm`` /
``JacoHand``. ``build_scene`` composes them with ``dm_control.mjcf`` and compiles the result with
plain ``mujoco.MjModel.from_xml_string``: the physics loop then uses MuJoCo's own bindings
(no ``mjcf.Physics`` wrapper, see docs/sim.md), and ``Scene`` keeps the indices it needs.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from dm_control import composer, mjcf
from dm_control.entities.manipulators.kinova import JacoArm, JacoHand, assets_path

from sim.config import MODELS_DIR, SimConfig
from sim.errors import SimError

LARGE_JOINTS = ("joint_1", "joint_2", "joint_3")
# The JACO hand's bodies of one finger: the proximal link (knuckle) and the distal one (tip).
FINGER_BODIES = tuple((f"b_finger_{k}", f"b_finger_tip_{k}") for k in (1, 2, 3))
# Pairs of bodies of different fingers that keep at least ~1 cm apart over the fingers' whole
# joint ranges (tests/test_sim_scene.py measures it), so MuJoCo need not test them for contact:
# their convex mesh hulls are the costliest pairs of a grasp.  The two tips that nearly meet
# when fingers 1 and 3 close on nothing (0.2 mm apart) keep colliding.
NEAR_FINGER_PAIRS = frozenset({("b_finger_tip_1", "b_finger_tip_3")})
UNREACHABLE_FINGER_PAIRS = tuple(
    (a, b) for i, one in enumerate(FINGER_BODIES) for other in FINGER_BODIES[i + 1:]
    for a in one for b in other if (a, b) not in NEAR_FINGER_PAIRS)
CUBE_COLOURS = ((0.85, 0.2, 0.15, 1.0), (0.15, 0.35, 0.85, 1.0), (0.9, 0.75, 0.1, 1.0))


def load_fragment(path: Path) -> mjcf.RootElement:
    """Parse one MJCF file of ``models/``; any problem becomes a one-line SimError naming it."""
    if not path.is_file():
        raise SimError(f"{path}: model file not found")
    try:
        return mjcf.from_path(str(path))
    except Exception as exc:  # lxml, ValueError, KeyError...: all mean a malformed file
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise SimError(f"{path}: malformed model file: {reason}") from None


def _require(root: mjcf.RootElement, kind: str, name: str, path: Path):
    element = root.find(kind, name)
    if element is None:
        raise SimError(f"{path}: model file has no {kind} named {name!r}")
    return element


class Arena(composer.Entity):
    """Table, floor, lights, location markers A/B and the fixed workspace camera."""

    def _build(self, path: Path, config: SimConfig):
        self._mjcf_root = load_fragment(path)
        _require(self._mjcf_root, "camera", config.render.camera, path)
        for name, xy in (("location_a", config.scene.location_a), ("location_b", config.scene.location_b)):
            site = _require(self._mjcf_root, "site", name, path)
            site.pos = (xy[0], xy[1], site.pos[2] if site.pos is not None else 0.0)
        _require(self._mjcf_root, "geom", "table", path)
        self._mjcf_root.option.timestep = config.physics.timestep

    @property
    def mjcf_model(self):
        return self._mjcf_root


class Cube(composer.Entity):
    """A free cube; its geometry and mass come from ``models/cube.xml``."""

    def _build(self, path: Path, name: str, rgba: tuple[float, ...]):
        self._mjcf_root = load_fragment(path)
        self._mjcf_root.model = name
        self._geom = _require(self._mjcf_root, "geom", "cube", path)
        size = self._geom.size
        if self._geom.type != "box" or size is None or len(size) != 3 or not all(h > 0 for h in size):
            raise SimError(f"{path}: geom 'cube' must be a box with 3 positive half-sizes")
        self._geom.rgba = rgba

    @property
    def mjcf_model(self):
        return self._mjcf_root

    @property
    def geom(self):
        return self._geom


def _set_armature(arm: JacoArm, config: SimConfig) -> None:
    """Lighter armature than dm_control's 4 / 2: with gravity compensation the arm tracks within mm."""
    for joint in arm.joints:
        joint.armature = config.arm.armature_large if joint.name in LARGE_JOINTS else config.arm.armature_small


def _exclude_unreachable_finger_pairs(hand: JacoHand) -> None:
    """``<exclude>`` the finger body pairs that cannot touch (``UNREACHABLE_FINGER_PAIRS``)."""
    for a, b in UNREACHABLE_FINGER_PAIRS:
        hand.mjcf_model.contact.add("exclude", body1=hand.mjcf_model.find("body", a),
                                    body2=hand.mjcf_model.find("body", b))


def _compile(root: mjcf.RootElement, gravcomp_bodies: list[str], sources: dict[str, Path]) -> mujoco.MjModel:
    """Compile with MuJoCo's MjSpec; dm_control's MJCF schema predates ``gravcomp``, so set it here.

    ``sources`` maps name prefixes ("cube_0/") to their file, so that an error names its file.
    """
    try:
        spec = mujoco.MjSpec.from_string(root.to_xml_string(), assets=root.get_assets())
        for name in gravcomp_bodies:
            spec.body(name).gravcomp = 1.0
        return spec.compile()
    except (ValueError, mujoco.FatalError) as exc:
        message = " ".join(str(exc).split())
        culprit = next((path for prefix, path in sources.items() if prefix and f"'{prefix}" in message), sources[""])
        raise SimError(f"{culprit}: model does not compile: {message}") from None


@dataclass(frozen=True)
class Scene:
    """A compiled scene and the indices the physics loop reads and writes."""

    model: mujoco.MjModel
    arm_qpos: np.ndarray       # qpos addresses of joints 1-6
    arm_dof: np.ndarray        # dof addresses of joints 1-6
    arm_actuators: np.ndarray
    finger_qpos: np.ndarray
    finger_range: np.ndarray   # (3, 2)
    finger_actuators: np.ndarray
    tool_site: int             # the hand's pinch site: the grasp point
    wrist_site: int
    cube_qpos: np.ndarray      # start address of each cube's free joint
    cube_geoms: np.ndarray
    cube_half_size: float
    finger_geoms: tuple[frozenset[int], ...]  # geoms of finger 1, 2, 3
    hand_geoms: frozenset[int]  # everything on the hand, fingers included
    table_geom: int
    location_a: np.ndarray
    location_b: np.ndarray


def build_scene(config: SimConfig, models_dir: Path = MODELS_DIR) -> Scene:
    """Compose arena, arm, hand and one cube per configured offset; compile; index."""
    models_dir = Path(models_dir)
    arena = Arena(models_dir / "scene.xml", config)
    arm, hand = JacoArm(), JacoHand(use_pinch_site_as_tcp=True)
    arm.attach(hand, arm.wrist_site)
    _exclude_unreachable_finger_pairs(hand)
    _set_armature(arm, config)
    arena.attach(arm).pos = config.arm.base_pos
    cube_path = models_dir / "cube.xml"
    cubes = [Cube(cube_path, f"cube_{i}", CUBE_COLOURS[i % len(CUBE_COLOURS)])
             for i in range(len(config.scene.cube_offsets))]
    cube_joints = [arena.attach(cube).add("freejoint", name="free") for cube in cubes]
    arm_bodies = [b.full_identifier for b in arm.mjcf_model.find_all("body")]  # includes the hand
    sources = {"": models_dir / "scene.xml", "jaco_arm/": Path(assets_path.KINOVA_ROOT)}
    sources |= {f"{cube.mjcf_model.model}/": cube_path for cube in cubes}
    model = _compile(arena.mjcf_model, arm_bodies if config.arm.gravity_compensation else [], sources)

    def ids(kind, elements) -> np.ndarray:
        return np.array([mujoco.mj_name2id(model, kind, e.full_identifier) for e in elements])

    arm_joints = ids(mujoco.mjtObj.mjOBJ_JOINT, arm.joints)
    finger_joints = ids(mujoco.mjtObj.mjOBJ_JOINT, hand.joints)
    finger_geoms = tuple(
        frozenset(int(g) for g in ids(mujoco.mjtObj.mjOBJ_GEOM, hand.mjcf_model.find_all("geom"))
                  if model.body(model.geom_bodyid[g]).name.endswith((f"finger_{k}", f"finger_tip_{k}")))
        for k in (1, 2, 3))
    return Scene(
        model=model,
        arm_qpos=model.jnt_qposadr[arm_joints],
        arm_dof=model.jnt_dofadr[arm_joints],
        arm_actuators=ids(mujoco.mjtObj.mjOBJ_ACTUATOR, arm.actuators),
        finger_qpos=model.jnt_qposadr[finger_joints],
        finger_range=model.jnt_range[finger_joints].copy(),
        finger_actuators=ids(mujoco.mjtObj.mjOBJ_ACTUATOR, hand.actuators),
        tool_site=int(ids(mujoco.mjtObj.mjOBJ_SITE, [hand.pinch_site])[0]),
        wrist_site=int(ids(mujoco.mjtObj.mjOBJ_SITE, [arm.wrist_site])[0]),
        cube_qpos=model.jnt_qposadr[ids(mujoco.mjtObj.mjOBJ_JOINT, cube_joints)],
        cube_geoms=ids(mujoco.mjtObj.mjOBJ_GEOM, [c.geom for c in cubes]),
        cube_half_size=float(model.geom_size[ids(mujoco.mjtObj.mjOBJ_GEOM, [cubes[0].geom])[0], 0]),
        finger_geoms=finger_geoms,
        hand_geoms=frozenset(int(g) for g in ids(mujoco.mjtObj.mjOBJ_GEOM, hand.mjcf_model.find_all("geom"))),
        table_geom=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "table"),
        location_a=np.array(config.scene.location_a, dtype=float),
        location_b=np.array(config.scene.location_b, dtype=float),
    )
