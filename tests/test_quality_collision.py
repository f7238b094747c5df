"""Collision last (issue 8 item 3): with ``solver.collision_last`` no moving particle ends a
step inside a collider. A tail whipping at 1 rev/s through a sphere (point and edge modes):
after every frame, the last step's positions are checked against the collider's pose of that
step (``ColliderState.start_new``), and the displayed bones against the scene's sphere.
Particles that start a step inside a moving collider: tests/test_quality_collision_moving.py.
"""
import importlib.util
import pathlib

import numpy as np
import pytest

from magica_py.bench.variants import prepare

ROOT = pathlib.Path(__file__).resolve().parents[1]
SPHERE_RADIUS = 0.12


@pytest.fixture(scope="module")
def bq(tmp_path_factory):
    spec = importlib.util.spec_from_file_location("bench_quality", ROOT / "benchmarks" / "bench_quality.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.SCENES = module.scenes(tmp_path_factory.mktemp("quality_scenes"))
    return module


def penetrations(bq, name, params, duration=2.0):
    """Max depth (m) inside sphere + particle radius: (end of step, display)."""
    path, raw, _ = bq.SCENES[name]
    p = prepare(bq.variant((path, raw, duration), "t", params))
    system, h = p.system, p.scene.hierarchy
    m = system.model
    moving = (np.asarray(m.attribute) & 0x02) != 0
    radius = system.parameters.radius_curve[0, 0]
    nodes = np.asarray(m.transform_index)
    ball = h.index("ball")
    cs = system.collider_state
    step_depth = display_depth = 0.0
    for _ in range(p.frames):
        p.player.step()
        centre = cs.start_new[0]                               # the sphere at the last step
        d = np.linalg.norm(system.particles.old_pos[moving] - centre, axis=1)
        step_depth = max(step_depth, float((SPHERE_RADIUS + radius - d).max()))
        d = np.linalg.norm(h.world_position[nodes][moving] - h.world_position[ball], axis=1)
        display_depth = max(display_depth, float((SPHERE_RADIUS + radius - d).max()))
    return step_depth, display_depth


@pytest.mark.parametrize("name", ["tail_sphere", "tail_sphere_edge"])
def test_collision_last_leaves_no_particle_inside_the_sphere_at_the_end_of_a_step(bq, name):
    step, _display = penetrations(bq, name, bq.QUALITY)
    assert step <= 1e-9
    off_step, _ = penetrations(bq, name, {**bq.QUALITY, "solver.collision_last": "disabled"})
    faithful_step, _ = penetrations(bq, name, bq.FAITHFUL)
    assert off_step > 1e-3 and faithful_step > 1e-3     # measured 14-42 mm and 10-19 mm


def state_edge_stretch(bq, name, params, duration=2.0):
    """Max stretch of each parent link (root first) over the two states of every frame."""
    path, raw, _ = bq.SCENES[name]
    p = prepare(bq.variant((path, raw, duration), "t", params))
    system = p.system
    ps = system.particles
    parent = np.asarray(system.model.parent)
    child = np.nonzero(parent >= 0)[0]
    dt = 1.0 / p.frequency
    rest, worst = None, np.zeros(child.size)
    for _ in range(p.frames):
        p.player.step()
        if rest is None:   # the step-basic pose, set by the first step
            rest = np.linalg.norm(ps.step_basic_pos[child] - ps.step_basic_pos[parent[child]], axis=1)
            if rest.min() <= 0.0:
                rest = None
                continue
        for x in (np.asarray(ps.old_pos), np.asarray(ps.old_pos - ps.real_velocity * dt)):
            worst = np.maximum(worst, np.linalg.norm(x[child] - x[parent[child]], axis=1) / rest - 1.0)
    return worst


def test_a_root_passing_through_a_sphere_stretches_only_its_own_edge_and_the_display_stays_outside(bq):
    """The root passes inside the sphere: the state cannot keep its first edge and stay out
    of it, and collision wins there (7.1 %); the chain's other edges are held by the
    collider-aware follow-the-leader after collision last (``quality.ftl_collision_lane``;
    before it: 24.1 % and 5.3 % on the first two edges). The quality display, within the
    lengths of the states it interpolates (tests/test_quality_display.py), shows no moving
    particle deeper inside the sphere than the state has one (0; only the fixed root, which
    cannot move, is inside): its target is pushed onto the circle where the sphere meets the
    ball of the edge's bound around the parent (``quality_display.frame_collider_push_bounded``), and the
    whole team moves to it by one common fraction. Before: 21.9 mm (faithful 15.6 mm)."""
    params = {"inertia.movement_inertia_smoothing": 0.0}
    stretch = state_edge_stretch(bq, "tail_sphere", {**bq.QUALITY, **params})
    assert stretch[0] > 0.02                     # the root's edge: collision wins (measured 7.1 %)
    assert stretch[1:].max() <= 1e-3             # the others are held (main: 5.3 % on the second)
    step, display = penetrations(bq, "tail_sphere", {**bq.QUALITY, **params})
    assert step <= 1e-9
    assert display <= step + 1e-6                # measured 1.5e-12 m (21.9 mm before)


CAPSULE_RADIUS = 0.12
CAPSULE_LENGTH = 0.4


def capsule_scene(bq, folder):
    """``tail_sphere`` with the sphere replaced by a capsule through the same centre, along x
    (radius 0.12 m, 0.4 m tip to tip, centred on its transform): the fixed root passes
    through it too, near the middle of its axis."""
    import yaml

    doc = yaml.safe_load(pathlib.Path(bq.SCENES["tail_sphere"][0]).read_text())
    doc["scene"]["name"] = "tail_capsule"
    doc["colliders"] = [{"name": "ball_col", "transform": "ball",
                         "capsule": {"radius": CAPSULE_RADIUS, "length": CAPSULE_LENGTH, "direction": "x",
                                     "aligned_on_center": True}}]
    path = folder / "tail_capsule.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


def segment_distance(x, a, b):
    """Distance (m) of points x (n, 3) from the segment a-b."""
    ab = b - a
    t = np.clip(((x - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(x - (a + t[:, None] * ab), axis=1)


def test_the_display_stays_outside_a_capsule_the_root_passes_through(bq, tmp_path):
    """The capsule case of the display's bounded push (``quality_display.frame_collider_push_bounded``
    works on the capsule's local sphere, the sphere around the axis point nearest the
    particle): no moving particle ends a step inside the capsule, and the display shows one at
    most 1 % of the particle radius deep (measured 0.064 mm; 32.3 mm before the bounded push
    and the common move): the local sphere is exact for a sphere, within a fraction of a
    millimetre for a capsule. The capsule is static, so its segment at the last step
    (``system.collider_state.start_new`` / ``end_new``) is its pose for the display too; the same run
    with collision last disabled enters it."""
    path = capsule_scene(bq, tmp_path)

    def depths(params):
        p = prepare(bq.variant((path, {}, 2.0), "t", params))
        system, h = p.system, p.scene.hierarchy
        m = system.model
        moving = (np.asarray(m.attribute) & 0x02) != 0
        radius = system.parameters.radius_curve[0, 0]
        nodes = np.asarray(m.transform_index)
        cs = system.collider_state
        step_depth = display_depth = 0.0
        for _ in range(p.frames):
            p.player.step()
            a, b = np.array(cs.start_new[0]), np.array(cs.end_new[0])
            reach = CAPSULE_RADIUS + radius
            step_depth = max(step_depth, float((reach - segment_distance(system.particles.old_pos[moving], a, b)).max()))
            display_depth = max(display_depth, float((reach - segment_distance(h.world_position[nodes][moving], a, b)).max()))
        assert np.linalg.norm(b - a) == pytest.approx(CAPSULE_LENGTH - 2 * CAPSULE_RADIUS, abs=1e-9)
        return step_depth, display_depth, radius

    params = {**bq.QUALITY, "inertia.movement_inertia_smoothing": 0.0}
    step, display, radius = depths(params)
    assert step <= 1e-9
    assert display <= step + 0.01 * radius       # measured 6.4e-5 m (0.032 m before)
    off_step, _, _ = depths({**params, "solver.collision_last": "disabled"})
    assert off_step > 1e-3                       # without collision last the tail enters it


def test_start_depth_finds_particles_already_inside_at_the_previous_pose():
    """The "was already inside" test of collision last: sphere, tapered capsule and plane at
    their previous-step pose, with the particle radius and the 1 um tolerance."""
    from magica_py.solver import state as st
    from magica_py.solver.quality import INSIDE_TOLERANCE, start_depth

    # three collider slots (sphere, tapered capsule along x, plane y = 0) of lane 0
    cs = st.COLLIDER.allocate(3)
    shape = (0, 1, 2)
    for name, values in (("start_old", [[0.0, 0, 0], [0, 0, 0], [0, 0, 0]]),
                         ("end_old", [[0.0, 0, 0], [1, 0, 0], [0, 0, 0]]),
                         ("radius_start", [0.5, 0.2, 0.0]), ("radius_end", [0.5, 0.1, 0.0]),
                         ("plane_normal", [[0.0, 1, 0], [0, 1, 0], [0, 1, 0]])):
        st.COLLIDER.write(cs, name, slice(None), 0, values)

    def inside(k, x, r):
        return start_depth(cs, k, 0, shape[k], x, r) > INSIDE_TOLERANCE

    r = 0.02
    assert inside(0, (0.5, 0.0, 0.0), r)             # inside sphere + radius
    assert not inside(0, (0.52, 0.0, 0.0), r)        # on the surface: not inside
    assert inside(1, (1.0, 0.11, 0.0), r)            # capsule end radius 0.1 + 0.02
    assert not inside(1, (1.0, 0.13, 0.0), r)
    assert inside(1, (0.0, 0.2, 0.0), r)             # start radius 0.2
    assert inside(2, (5.0, 0.01, 3.0), r)            # plane y = 0, within r
    assert not inside(2, (5.0, 0.03, 3.0), r)
