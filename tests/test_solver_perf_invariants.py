"""The speed work keeps the maths bit for bit (issue 4 "Speed"): each hoisted or cached
quantity equals, exactly, what the reference-order evaluation gives. The golden hashes of the
showcase scenes are checked by tests/test_quality_faithful_unchanged.py."""
from __future__ import annotations

import math
import pathlib

import numba
import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, load3, lerp, q_look_rotation, v_add, v_cross, v_dot, v_length,
    v_normalize, v_scale,
)
from magica_py.runtime.player import Player
from magica_py.solver.constraints.angle import angle_team
from magica_py.solver.constraints.bending import DONT_MOVE_INVERSE_MASS, bending_team, solve_dihedral
from magica_py.solver.parameters import curve_at_clamp01, step_rate
from magica_py.solver.rotations import triangle_frame_from, triangle_rotations_team
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parent.parent


@numba.njit
def triangle_frame(m, ps, tri):
    """Normal and uv tangent of triangle ``tri`` at the display positions (0 when degenerate)."""
    return triangle_frame_from(load3(ps.position, m.triangles[tri, 0]), load3(ps.position, m.triangles[tri, 1]),
                               load3(ps.position, m.triangles[tri, 2]),
                               (m.triangle_uv[tri, 0, 0], m.triangle_uv[tri, 0, 1]),
                               (m.triangle_uv[tri, 1, 0], m.triangle_uv[tri, 1, 1]),
                               (m.triangle_uv[tri, 2, 0], m.triangle_uv[tri, 2, 1]))


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


def test_triangle_frames_computed_once_equal_the_per_vertex_pair_evaluation(walk):
    s = walk
    m, ps = s.model, s.particles
    team = _team(s, "skirt")
    assert m.team_triangle_count[team] > 0
    tables = s.kernel_tables()
    before = ps.rotation.copy()
    triangle_rotations_team(tables[0], tables[1], team)
    got = ps.rotation.copy()
    ps.rotation[...] = before
    # reference order: the frame of each (vertex, triangle) pair evaluated on the spot
    sl = s.team_particles(team)
    changed = 0
    for p in range(sl.start, sl.stop):
        n = int(m.vertex_triangle_count[p])
        if n == 0:
            assert np.array_equal(got[p], before[p])
            continue
        ns = (0.0, 0.0, 0.0)
        ts_ = (0.0, 0.0, 0.0)
        for k in range(int(m.vertex_triangle_start[p]), int(m.vertex_triangle_start[p]) + n):
            tn, tt = triangle_frame(tables[0], tables[1], int(m.vertex_triangle_data[k]))
            flip = int(m.vertex_triangle_flip[k])
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
    m, ps, prm = s.model, s.particles, s.parameters
    team = _team(s, "skirt")
    assert m.team_bend_count[team] > 0
    tables = s.kernel_tables()
    ps.accum_vector[...] = 0.0
    ps.accum_count[...] = 0
    bending_team(tables[0], tables[1], tables[2], tables[3], team, 1.0, 1.0)
    got = ps.accum_vector.copy(), ps.accum_count.copy()
    ps.accum_vector[...] = 0.0
    ps.accum_count[...] = 0

    def w(v):
        if (m.attribute[v] & 0x02) == 0:
            return DONT_MOVE_INVERSE_MASS
        return inverse_mass_friction_depth(float(ps.friction[v]), float(m.depth[v]))

    k = min(max(step_rate(float(prm.bending_stiffness[team]), 1.0, 1.0, int(prm.rate_mode[team])), 0.0), 1.0)
    acc = np.zeros_like(ps.accum_vector)
    cnt = np.zeros_like(ps.accum_count)
    b0 = int(m.team_bend_start[team])
    for b in range(b0, b0 + int(m.team_bend_count[team])):
        v = [int(x) for x in m.bend_vertices[b]]
        ok, *corr = solve_dihedral(*(tuple(ps.next_pos[i]) for i in v), *(w(i) for i in v),
                                   float(m.bend_rest_angle[b]), float(m.bend_sign[b]), k)
        if ok:
            for i, c in zip(v, corr):
                acc[i] += [float(math.trunc(x * 1e6)) for x in c]
                cnt[i] += 1
    assert m.team_volume_count[team] == 0  # the skirt preset builds no volume pairs
    assert np.array_equal(got[0], acc) and np.array_equal(got[1], cnt)
    assert cnt.sum() > 0 and np.abs(acc).max() > 0


def test_restoration_stiffness_and_rest_direction_buffers_equal_the_per_iteration_values(walk):
    s = walk
    m, ps, prm, ts = s.model, s.particles, s.parameters, s.teams
    tables = s.kernel_tables()
    for name in ("hair", "skirt"):
        team = _team(s, name)
        assert prm.use_restoration[team]
        saved = {f: getattr(ps, f).copy() for f in ("next_pos", "velocity_pos", "angle_rotation")}
        angle_team(tables[0], tables[1], tables[2], tables[3], team, 1.0, 1.0, 0.9, 0.8)
        for f, a in saved.items():
            getattr(ps, f)[...] = a
        gravity_factor = lerp(1.0 - float(prm.restoration_gravity_falloff[team]), 1.0, float(ts.gravity_dot[team]))
        checked = 0
        b0 = int(m.team_baseline_start[team])
        for b in range(b0, b0 + int(m.team_baseline_count[team])):
            e0 = int(m.baseline_start[b])
            for e in range(e0 + 1, e0 + int(m.baseline_count[b])):
                c = int(m.baseline_data[e])
                kr = curve_at_clamp01(prm.restoration_stiffness_curve, team, float(m.depth[c]))
                expected = min(max(step_rate(kr, 1.0, 1.0, int(prm.rate_mode[team])), 0.0), 1.0) * gravity_factor
                assert ps.angle_restoration_k[c] == expected
                # the rest direction, hoisted out of the iterations: |bv| and bv / |bv|
                bv = tuple(ps.step_basic_pos[c] - ps.step_basic_pos[int(m.parent[c])])
                assert ps.angle_rest_length[c] == v_length(bv)
                assert tuple(ps.angle_rest_direction[c]) == v_scale(bv, 1.0 / v_length(bv))
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
