"""The speed work keeps the maths bit for bit (issue 4 "Speed"): each hoisted or cached
quantity equals, exactly, what the reference-order evaluation gives; and a scene compiles and
calls only the optional stages its cloths use. The golden hashes of the showcase scenes are
checked by tests/test_quality_faithful_unchanged.py, the lane form against the per-team
reference by tests/test_lane_equivalence.py.

The stage drivers are called here on the tables of a real ``ClothSystem`` (``system.tables``),
one block at a time; the system's state is put back after each call."""
from __future__ import annotations

import math
import pathlib

import numba
import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, lerp, q_look_rotation, v_add, v_cross, v_dot, v_length, v_normalize, v_scale,
)
from magica_py.runtime.player import Player
from magica_py.solver import blocks as bk
from magica_py.solver.constraints.angle import angle_block
from magica_py.solver.constraints.bending import DONT_MOVE_INVERSE_MASS, FIXED_POINT, bending_block, solve_dihedral
from magica_py.solver.frame import simulate_frame
from magica_py.solver.parameters import (
    PRM_RESTORATION_STIFFNESS_CURVE, constraint_stiffness, curve_at_clamp01, step_rate,
)
from magica_py.solver.rotations import triangle_frame_from, triangle_rotations_block
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def walk():
    """The walking character after 25 frames: skirt (mesh: triangles, bending) and hair."""
    scene = load_scene(ROOT / "configs" / "character_walk.yaml")
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    player.run(25)
    return system


def _team(system, name):
    return system.team_names.index(name)


class _StateKept:
    """Puts the system's state tables back (in place) when the block leaves."""

    def __init__(self, system):
        self.system = system

    def __enter__(self):
        s = self.system
        self.saved = {name: getattr(s, name).copy() for name in ("PS", "TS", "CS", "TRS", "EDS")}
        return self

    def __exit__(self, *exc):
        for name, a in self.saved.items():
            getattr(self.system, name)[...] = a


def test_triangle_frames_computed_once_equal_the_per_vertex_pair_evaluation(walk):
    s = walk
    team = _team(s, "skirt")
    model = s.models[team]
    assert len(model.triangles) > 0
    T = s.tables
    b, lane, g = s.team_slots(team)
    tri = s.layout.slots(team)["triangle"]
    uv = bk.TRIANGLE_MODEL.view(T.TRM, "triangle_uv", tri, lane)      # (triangles, 6)
    before = s.read_particles(team, "rotation")
    position = s.read_particles(team, "position")
    with _StateKept(s):
        triangle_rotations_block(T.PS, T.TRS, T.TRM, T.BI, T.topology, np.int32(b))
        got = s.read_particles(team, "rotation")
    assert s.read_particles(team, "rotation").tobytes() == before.tobytes()   # state put back

    def frame(t):
        a, bb, c = (int(v) for v in model.triangles[t])
        return triangle_frame_from(tuple(position[a]), tuple(position[bb]), tuple(position[c]),
                                   (uv[t, 0], uv[t, 1]), (uv[t, 2], uv[t, 3]), (uv[t, 4], uv[t, 5]))

    # reference order: the frame of each (vertex, triangle) pair evaluated on the spot, the
    # rotation from the normalised sums (the pre-select form of the helpers)
    changed = 0
    for p in range(model.particle_count):
        n = int(model.vertex_triangle_count[p])
        if n == 0:
            assert np.array_equal(got[p], before[p])
            continue
        ns = (0.0, 0.0, 0.0)
        ts_ = (0.0, 0.0, 0.0)
        for k in range(int(model.vertex_triangle_start[p]), int(model.vertex_triangle_start[p]) + n):
            tn, tt = frame(int(model.vertex_triangle_data[k]))
            flip = int(model.vertex_triangle_flip[k])
            ns = v_add(ns, v_scale(tn, -1.0 if flip & 1 else 1.0))
            ts_ = v_add(ts_, v_scale(tt, -1.0 if flip & 2 else 1.0))
        expected = before[p]
        if v_length(ns) > 1e-6 and v_length(ts_) > 1e-6:
            nn, tn = v_normalize(ns), v_normalize(ts_)
            if abs(v_dot(nn, tn)) < 1.0 - 1e-9:
                expected = np.array(q_look_rotation(v_normalize(v_cross(nn, tn)), nn))
                changed += 1
        assert np.array_equal(got[p], expected), f"particle {p}"
    assert changed > 10


def test_bending_with_per_pass_inverse_masses_equals_per_pair_masses(walk):
    s = walk
    team = _team(s, "skirt")
    model = s.models[team]
    assert len(model.bend_vertices) > 0
    assert len(getattr(model, "volume_vertices", ())) == 0   # the skirt preset builds no volume pairs
    T = s.tables
    b, lane, g = s.team_slots(team)
    next_pos = s.read_particles(team, "next_pos")
    friction = s.read_particles(team, "friction")
    assert not s.read_particles(team, "accum_count").any()  # the accumulators are clear between passes
    with _StateKept(s):
        bending_block(T.PS, T.PM, T.TS, T.BM, T.VM, T.P, T.BI, T.topology, np.int32(b), 1.0, 1.0)
        got = s.read_particles(team, "next_pos")
        assert not s.read_particles(team, "accum_count").any()   # and cleared after it

    def w(v):
        if (model.attribute[v] & 0x02) == 0:
            return DONT_MOVE_INVERSE_MASS
        return inverse_mass_friction_depth(float(friction[v]), float(model.depth[v]))

    prm = s.parameters
    k = min(max(constraint_stiffness(float(prm.bending_stiffness[team]), 1.0, 1.0, int(prm.rate_mode[team]),
                                     int(prm.quality[team])), 0.0), 1.0)
    assert k == min(max(step_rate(float(prm.bending_stiffness[team]), 1.0, 1.0, 0), 0.0), 1.0)   # faithful
    acc = np.zeros((model.particle_count, 3))
    cnt = np.zeros(model.particle_count, dtype=np.int64)
    rest = bk.BEND_MODEL.view(T.BM, "bend_rest_angle", s.layout.slots(team)["bend"], lane)
    sign = bk.BEND_MODEL.view(T.BM, "bend_sign", s.layout.slots(team)["bend"], lane)
    np.testing.assert_array_equal(rest, model.bend_rest_angle)
    for e in range(len(model.bend_vertices)):
        v = [int(x) for x in model.bend_vertices[e]]
        ok, *corr = solve_dihedral(*(tuple(next_pos[i]) for i in v), *(w(i) for i in v),
                                   float(rest[e]), float(sign[e]), k)
        if ok:
            for i, c in zip(v, corr):
                acc[i] += [float(math.trunc(x * FIXED_POINT)) for x in c]
                cnt[i] += 1
    expected = next_pos.copy()
    for p in range(model.particle_count):
        if (model.attribute[p] & 0x02) and cnt[p] > 0:
            scale = 1.0 / (cnt[p] * FIXED_POINT)
            expected[p] = next_pos[p] + acc[p] * scale
    assert cnt.sum() > 0 and np.abs(acc).max() > 0
    assert got.tobytes() == expected.tobytes()


def test_restoration_stiffness_and_rest_direction_buffers_equal_the_per_iteration_values(walk):
    s = walk
    prm = s.parameters
    T = s.tables
    for name in ("hair", "skirt"):
        team = _team(s, name)
        model = s.models[team]
        assert prm.use_restoration[team]
        b, lane, g = s.team_slots(team)
        with _StateKept(s):
            angle_block(T.PS, T.PP, T.TS, T.P, T.BI, T.topology, np.int32(b), 1.0, 1.0, 0.9, 0.8)
            k_buffer = s.read_particles(team, "angle_restoration_k")
            length_buffer = s.read_particles(team, "angle_rest_length")
            direction_buffer = s.read_particles(team, "angle_rest_direction")
            basic = s.read_particles(team, "step_basic_pos")      # not written by the angle pass
        gravity_factor = lerp(1.0 - float(prm.restoration_gravity_falloff[team]), 1.0,
                              float(s.read_team(team, "gravity_dot")))
        checked = 0
        for line in range(len(model.baseline_start)):
            e0 = int(model.baseline_start[line])
            for e in range(e0 + 1, e0 + int(model.baseline_count[line])):
                c = int(model.baseline_data[e])
                # the curve looked up by depth (what each iteration would do), not the cached PP
                kr = curve_at_clamp01(T.P, b, PRM_RESTORATION_STIFFNESS_CURVE, float(model.depth[c]))
                expected = min(max(step_rate(kr, 1.0, 1.0, int(prm.rate_mode[team])), 0.0), 1.0) * gravity_factor
                assert k_buffer[c] == expected
                # the rest direction, hoisted out of the iterations: |bv| and bv / |bv|
                bv = tuple(basic[c] - basic[int(model.parent[c])])
                assert length_buffer[c] == v_length(bv)
                assert tuple(direction_buffer[c]) == v_scale(bv, 1.0 / v_length(bv))
                checked += 1
        assert checked > 10


# The golden-hash bit-identity check of faithful mode lives in
# tests/test_quality_faithful_unchanged.py (every showcase, configs as of the golden commit).


@pytest.mark.parametrize("config", ["character_walk", "crowd", "tail_orbit", "hitches_and_events"])
def test_baselines_list_every_parent_before_its_child(config):
    """The angle pass buffers per-particle values (inverse mass) in baseline order and reads
    the parent's: valid because a baseline lists each particle's parent before it (B.6)."""
    from magica_py.build import build_cloth

    scene = load_scene(ROOT / "configs" / f"{config}.yaml")
    checked = 0
    for spec in scene.cloths[:4]:
        m = build_cloth(scene.hierarchy, spec)
        for b in range(len(m.baseline_count)):
            e0 = int(m.baseline_start[b])
            data = [int(x) for x in m.baseline_data[e0:e0 + int(m.baseline_count[b])]]
            for k in range(1, len(data)):
                assert int(m.parent[data[k]]) in data[:k]
                checked += 1
    assert checked > 0


ON = 1
# the optional stages each showcase's cloths use (frame.StageSwitches), from the configs:
# tail_orbit is one line-mode tail with angle restoration and no collider (so not even the
# colliders' poses are tracked); the character's skirt is a sequential loop mesh (bending,
# triangles) with point-mode colliders
STAGES = {
    "tail_orbit": dict(angle=ON, bending=None, point_collision=None, edge_collision=None, motion=None,
                       quality=None, lines=ON, triangles=None, wind=None, colliders=None),
    "character_walk": dict(angle=ON, bending=ON, point_collision=ON, edge_collision=None, motion=None,
                           quality=None, lines=ON, triangles=ON, wind=None, colliders=ON),
}


@pytest.mark.parametrize("config", sorted(STAGES))
def test_a_scene_switches_on_only_the_stages_its_cloths_use(config, used_stages):
    """``ClothSystem.stages`` (the frame kernel's ``StageSwitches``) names the stages a scene
    needs; the others are passed as None, so numba prunes their calls before typing them (the
    compile events of tests/test_jit_off.py show they are never compiled)."""
    scene = load_scene(ROOT / "configs" / f"{config}.yaml")
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    assert system.stages._asdict() == STAGES[config]
    player.run(2)
    # the frame kernel was typed with exactly these switches: None where a stage is unused
    switches = tuple(numba.types.none if v is None else numba.typeof(v) for v in system.stages)
    assert any(tuple(sig[-len(switches):]) == switches for sig in simulate_frame.signatures), \
        simulate_frame.signatures


def _run_state(config, frames):
    """Every state table of ``config``'s cloth system after ``frames`` frames (a policy of
    ``MAGICA_STAGES`` set by the caller), the system's switches and the bones' local rotations."""
    scene = load_scene(ROOT / "configs" / f"{config}.yaml")
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    player.run(frames)
    tables = {name: getattr(system, name).copy() for name in ("PS", "TS", "CS", "TRS", "EDS")}
    return tables, system.stages, scene.hierarchy.local_rotation.copy()


@pytest.mark.parametrize("config", sorted(STAGES))
def test_every_stage_compiled_gives_the_bits_of_the_stages_the_scene_uses(config, monkeypatch):
    """``MAGICA_STAGES=all`` compiles every optional stage; a stage no block asks for then runs
    its checks and changes nothing: every state table and every written bone rotation has the
    bits of the scene's own selection (``MAGICA_STAGES=used``), over frames with collisions
    (the character) and a first-frame reset. (The rest of the suite runs under ``all``: its
    golden hashes and oracles check the same on every scene it runs.)"""
    monkeypatch.setenv("MAGICA_STAGES", "used")
    used, used_switches, used_rotations = _run_state(config, 40)
    monkeypatch.setenv("MAGICA_STAGES", "all")
    every, every_switches, every_rotations = _run_state(config, 40)
    assert None in used_switches and None not in every_switches
    for name in used:
        assert used[name].tobytes() == every[name].tobytes(), name
    assert used_rotations.tobytes() == every_rotations.tobytes()
    assert np.isfinite(used["PS"]).all()


def test_a_bad_stage_policy_is_an_error_naming_the_variable(monkeypatch):
    """Where the policy is read (a cloth system's stage switches, a scene's driver kinds) a bad
    value is a ``ParameterError`` naming the variable, not an error of the scene's document."""
    from magica_py.params import ParameterError

    scene = load_scene(ROOT / "configs" / "tail_orbit.yaml")
    monkeypatch.setenv("MAGICA_STAGES", "some")
    expected = "^environment variable MAGICA_STAGES: 'some': expected 'used'.*or 'all'"
    with pytest.raises(ParameterError, match=expected):
        ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings)
    with pytest.raises(ParameterError, match=expected):
        load_scene(ROOT / "configs" / "tail_orbit.yaml")   # its animation's driver kinds


def test_a_runtime_change_switches_a_stage_on_and_off(used_stages):
    scene = load_scene(ROOT / "configs" / "character_walk.yaml")
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings)
    assert system.stages.edge_collision is None and system.stages.motion is None
    system.set_parameter("skirt", "collider_collision.mode", "edge")
    assert system.stages.edge_collision == ON and system.stages.point_collision == ON   # the hair still points
    system.set_parameter("hair", "collider_collision.mode", "edge")
    assert system.stages.point_collision is None
    # collision off everywhere: the colliders' poses are still tracked (a cloth with colliders),
    # so that collision switched on again starts from their current pose, not a stale one
    system.set_parameter("hair", "collider_collision.mode", "none")
    system.set_parameter("skirt", "collider_collision.mode", "none")
    assert system.stages.edge_collision is None and system.stages.point_collision is None
    assert system.stages.colliders == ON
    system.set_parameter("hair", "motion.use_max_distance", True)
    assert system.stages.motion == ON
    system.set_parameter("hair", "motion.use_max_distance", False)
    assert system.stages.motion is None
    system.remove_cloth(_team(system, "skirt"))
    assert system.stages.bending is None and system.stages.triangles is None and system.stages.lines == ON
