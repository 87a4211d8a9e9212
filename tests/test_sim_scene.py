"""The scene's contact filtering: what is excluded can never touch, what must touch still does."""
import sim  # noqa: F401  -- first: sim/__init__ selects headless EGL before mujoco loads
import itertools

import mujoco
import numpy as np
import pytest

from sim.env import ArmSim
from sim.scene import FINGER_BODIES, UNREACHABLE_FINGER_PAIRS

CLEARANCE = 0.005  # m: an excluded pair must keep at least this far apart
OVERSHOOT = 0.02   # rad: soft joint limits let a squeezing finger pass its range end a little


@pytest.fixture(scope="module")
def arm():
    arm = ArmSim()
    yield arm
    arm.close()


def _body(model: mujoco.MjModel, name: str) -> int:
    return next(b for b in range(model.nbody) if model.body(b).name.endswith(f"/{name}"))


def _contacts(arm: ArmSim) -> set[frozenset[int]]:
    return {frozenset(pair) for pair in arm._contact_pairs()}


def test_the_excluded_finger_pairs_are_exactly_the_listed_ones(arm):
    """Decode the compiled exclusions among finger bodies: nothing else is excluded, nothing is missing."""
    model = arm.model
    finger_bodies = {_body(model, name) for name in itertools.chain(*FINGER_BODIES)}
    compiled = set()
    for signature in model.exclude_signature.tolist():
        pair = frozenset({signature >> 16, signature & 0xFFFF})
        if pair <= finger_bodies:
            compiled.add(pair)
    listed = {frozenset({_body(model, a), _body(model, b)}) for a, b in UNREACHABLE_FINGER_PAIRS}
    assert compiled == listed
    assert len(listed) == 11  # 12 pairs of bodies of different fingers, less the two tips that can meet


def test_excluded_finger_pairs_keep_apart_over_the_whole_finger_ranges(arm):
    """A grid over the three finger angles (a little past both range ends): every excluded pair
    of geoms stays more than CLEARANCE apart, so the exclusion never lets fingers pass through."""
    model, data, scene = arm.model, arm.data, arm.scene
    geoms = {b: [g for g in range(model.ngeom) if model.geom_bodyid[g] == b] for b in range(model.nbody)}
    pairs = [(g1, g2) for a, b in UNREACHABLE_FINGER_PAIRS
             for g1 in geoms[_body(model, a)] for g2 in geoms[_body(model, b)]]
    lower, upper = scene.finger_range[:, 0] - OVERSHOOT, scene.finger_range[:, 1] + OVERSHOOT
    closest, fromto = np.inf, np.zeros(6)
    arm.reset()
    for fraction in itertools.product(np.linspace(0.0, 1.0, 9), repeat=3):
        data.qpos[scene.finger_qpos] = lower + np.array(fraction) * (upper - lower)
        mujoco.mj_kinematics(model, data)
        for g1, g2 in pairs:
            closest = min(closest, mujoco.mj_geomDistance(model, data, g1, g2, 0.05, fromto))
    assert closest > CLEARANCE


def test_the_two_tips_that_can_meet_still_collide(arm):
    """Fingers 1 and 3 squeezed a little past their range end on nothing: their tips touch."""
    model, data, scene = arm.model, arm.data, arm.scene
    arm.reset()
    data.qpos[scene.finger_qpos] = scene.finger_range[:, 1] + OVERSHOOT
    data.qpos[scene.finger_qpos[1]] = scene.finger_range[1, 0]  # finger 2 open, out of the way
    mujoco.mj_forward(model, data)
    tips = {_body(model, "b_finger_tip_1"), _body(model, "b_finger_tip_3")}
    assert any({int(model.geom_bodyid[g]) for g in pair} == tips for pair in _contacts(arm))


def test_every_finger_still_touches_a_cube_and_the_cubes_rest_on_the_table(arm):
    model, data, scene = arm.model, arm.data, arm.scene
    arm.reset()
    for _ in range(30):  # half a second at rest
        arm.step_twist((0.0, 0.0, 0.0))
    table = frozenset({scene.table_geom})
    assert all(arm.touching(frozenset({int(cube)}), table) for cube in scene.cube_geoms)
    assert np.allclose(arm.cube_positions[:, 2], scene.cube_half_size, atol=1e-3)
    # A cube between the closed fingers: each finger collides with it.
    cube = frozenset({int(scene.cube_geoms[0])})
    start = scene.cube_qpos[0]
    data.qpos[start:start + 3] = arm.tool_position
    data.qpos[scene.finger_qpos] = scene.finger_range[:, 1]
    mujoco.mj_forward(model, data)
    assert [arm.touching(finger, cube) for finger in scene.finger_geoms] == [True, True, True]
