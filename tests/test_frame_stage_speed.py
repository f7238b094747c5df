"""The per-frame stages rewritten to vectorise along a team's particles (skinning C.1, inertia
shift C.5, guards, E.3 triangle rotations, E.4 transform data) give exactly the bits of their
previous scalar formulation.

Oracle: slow Python twins of the previous per-particle code, built from the branchy
``kernels.math3d`` helpers (Python floats are IEEE doubles: the same operations in the same
order give the same bits), run on a mid-motion crowd state. The whole-solver check is
``benchmarks/golden_hashes.py --check``; these tests pin each stage on its own, including the
paths a crowd frame rarely takes (degenerate vectors, every case of the matrix-to-quaternion
selects, guard verdicts, the scalar pass for vertices with many triangles).
"""
import math

import numpy as np
import pytest

from batched_harness import crowd_system, restore, snapshot
from magica_py.kernels import math3d as m3
from magica_py.solver.center import reset_or_shift_team, skin_team
from magica_py.solver.guards import GUARD_NON_FINITE, GUARD_OK, GUARD_SPEED, check_team
from magica_py.solver.rotations import (
    TRIANGLES_PER_VERTEX, crowded_vertex_rotation, normalize_or_zero, q_from_matrix_select, q_normalize_or_identity,
    rot_from_normal_tangent_select, triangle_rotations_team,
)
from magica_py.solver.writeback import transform_data_team


@pytest.fixture(scope="module")
def crowd():
    return crowd_system(instances=2, frames=25)


def _bits(a):
    return np.asarray(a, dtype=np.float64).view(np.uint64)


def _teams(system):
    return [int(t) for t in system.model.live_teams]


def _rows(system, team):
    s = int(system.model.team_particle_start[team])
    return range(s, s + int(system.model.team_particle_count[team]))


# ----------------------------------------------------------------------------- branch-free helpers
def test_branch_free_helpers_equal_math3d_bit_for_bit_on_every_case():
    rng = np.random.default_rng(3)
    vectors = [tuple(v) for v in rng.normal(size=(300, 3))] + [(0.0, 0.0, 0.0), (1e-13, 0.0, -1e-13), (-0.0, 0.0, 0.0)]
    for v in vectors:
        assert _bits(normalize_or_zero(v)).tolist() == _bits(m3.v_normalize(v)).tolist()
    quats = [tuple(q) for q in rng.normal(size=(200, 4))] + [(0.0, 0.0, 0.0, 0.0), (1e-14, 0.0, 0.0, 0.0)]
    for q in quats:
        assert _bits(q_normalize_or_identity(q)).tolist() == _bits(m3.q_normalize(q)).tolist()
    cases = set()
    for _ in range(400):
        q = m3.q_normalize(tuple(rng.normal(size=4)))
        r = m3.q_to_matrix(q)
        args = (r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2])
        assert _bits(q_from_matrix_select(*args)).tolist() == _bits(m3.q_from_matrix(*args)).tolist()
        first = math.copysign(1.0, args[0]) >= 0.0
        t = args[4] + args[8] if first else args[4] - args[8]
        cases.add((first, math.copysign(1.0, t) >= 0.0))
    assert len(cases) == 4  # every branch of q_from_matrix was compared
    for n, t in zip(vectors[:100], vectors[100:200]):
        n, t = m3.v_normalize(n), m3.v_normalize(t)
        assert _bits(rot_from_normal_tangent_select(n, t)).tolist() == _bits(m3.rot_from_normal_tangent(n, t)).tolist()


# ----------------------------------------------------------------------------- C.1 skinning
def _transform_point(l2w, bind, v, w):
    b, L = bind, l2w
    x = b[0, 0] * v[0] + b[0, 1] * v[1] + b[0, 2] * v[2] + b[0, 3] * w
    y = b[1, 0] * v[0] + b[1, 1] * v[1] + b[1, 2] * v[2] + b[1, 3] * w
    z = b[2, 0] * v[0] + b[2, 1] * v[1] + b[2, 2] * v[2] + b[2, 3] * w
    h = b[3, 0] * v[0] + b[3, 1] * v[1] + b[3, 2] * v[2] + b[3, 3] * w
    return (L[0, 0] * x + L[0, 1] * y + L[0, 2] * z + L[0, 3] * h,
            L[1, 0] * x + L[1, 1] * y + L[1, 2] * z + L[1, 3] * h,
            L[2, 0] * x + L[2, 1] * y + L[2, 2] * z + L[2, 3] * h)


def test_skinning_gives_the_scalar_formulation_bits(crowd):
    m, ps, _prm, _ts, _cs, _tt, h = crowd.kernel_tables()
    model = crowd.model
    l2w = crowd._hierarchy.local_to_world
    before = snapshot(crowd)
    try:
        crowd.particles.position[:] = np.nan
        crowd.particles.rotation[:] = np.nan
        for t in _teams(crowd):
            skin_team(m, ps, l2w, t)
            for p in _rows(crowd, t):
                L = l2w[model.transform_index[p]]
                b = model.skin_bind_pose[p]
                pos = _transform_point(L, b, model.local_position[p], 1.0)
                nor = m3.v_normalize(_transform_point(L, b, model.local_normal[p], 0.0))
                tan = m3.v_normalize(_transform_point(L, b, model.local_tangent[p], 0.0))
                assert _bits(crowd.particles.position[p]).tolist() == _bits(pos).tolist(), p
                assert (_bits(crowd.particles.rotation[p]).tolist()
                        == _bits(m3.rot_from_normal_tangent(nor, tan)).tolist()), p
    finally:
        restore(crowd, before)


# ----------------------------------------------------------------------------- C.5 inertia shift
def test_inertia_shift_gives_the_scalar_formulation_bits(crowd):
    m, ps, _prm, ts, _cs, _tt, _h = crowd.kernel_tables()
    state, teams = crowd.particles, crowd.teams
    before = snapshot(crowd)
    try:
        rng = np.random.default_rng(5)
        expected = {}
        for t in _teams(crowd):
            teams.reset[t] = 0
            teams.inertia_shift[t] = 1
            teams.frame_shift_vector[t] = rng.normal(size=3) * 0.1
            teams.frame_shift_rotation[t] = m3.q_normalize(tuple(rng.normal(size=4)))
            pivot, vec, rot = tuple(teams.old_component_pos[t]), tuple(teams.frame_shift_vector[t]), tuple(teams.frame_shift_rotation[t])
            for p in _rows(crowd, t):
                expected[p] = (m3.shift_position(tuple(state.old_pos[p]), pivot, vec, rot),
                               m3.shift_position(tuple(state.old_position[p]), pivot, vec, rot),
                               m3.shift_position(tuple(state.disp_pos[p]), pivot, vec, rot),
                               m3.q_mul(rot, tuple(state.old_rotation[p])),
                               m3.q_rotate(rot, tuple(state.velocity[p])),
                               m3.q_rotate(rot, tuple(state.real_velocity[p])))
            reset_or_shift_team(m, ps, ts, t)
        fields = ("old_pos", "old_position", "disp_pos", "old_rotation", "velocity", "real_velocity")
        for p, want in expected.items():
            for name, value in zip(fields, want):
                assert _bits(getattr(state, name)[p]).tolist() == _bits(value).tolist(), (name, p)
    finally:
        restore(crowd, before)


# ----------------------------------------------------------------------------- guards
def test_guard_verdicts_healthy_speed_non_finite_and_both(crowd):
    m, ps, _prm, ts, _cs, _tt, _h = crowd.kernel_tables()
    state = crowd.particles
    team = _teams(crowd)[1]
    rows = list(_rows(crowd, team))
    before = snapshot(crowd)
    try:
        assert check_team(m, ps, ts, team) == GUARD_OK
        limit = 100.0 * max(float(crowd.teams.scale_ratio[team]), 1e-6)
        state.real_velocity[rows[3]] = (0.0, limit * 1.01, 0.0)
        assert check_team(m, ps, ts, team) == GUARD_SPEED
        state.real_velocity[rows[3]] = (0.0, limit * 0.99, 0.0)
        assert check_team(m, ps, ts, team) == GUARD_OK
        state.real_velocity[rows[-1]] = (0.0, 0.0, limit * 2.0)
        state.disp_pos[rows[0], 2] = np.inf  # an earlier particle non-finite, a later one too fast
        assert check_team(m, ps, ts, team) == GUARD_NON_FINITE
        state.disp_pos[rows[0], 2] = 0.0
        state.velocity[rows[-1], 0] = np.nan  # the last particle both too fast and NaN
        assert check_team(m, ps, ts, team) == GUARD_NON_FINITE
        # the neighbouring teams are untouched by the checks
        assert check_team(m, ps, ts, _teams(crowd)[0]) == GUARD_OK
    finally:
        restore(crowd, before)


# ----------------------------------------------------------------------------- E.4 transform data
def test_transform_data_gives_the_scalar_bits_and_rejects_non_finite(crowd):
    m, ps, _prm, _ts, _cs, _tt, _h = crowd.kernel_tables()
    state, model = crowd.particles, crowd.model
    before = snapshot(crowd)
    try:
        for t in _teams(crowd):
            assert transform_data_team(m, ps, t)
            for p in _rows(crowd, t):
                rot = m3.q_normalize(m3.q_mul(tuple(state.rotation[p]), tuple(model.vertex_to_transform_rotation[p])))
                assert _bits(state.transform_rotation[p]).tolist() == _bits(rot).tolist(), p
                assert _bits(state.transform_position[p]).tolist() == _bits(state.position[p]).tolist(), p
        t = _teams(crowd)[0]
        state.rotation[list(_rows(crowd, t))[-1]] = (0.0, 0.0, 0.0, 0.0)  # degenerate: identity, still finite
        assert transform_data_team(m, ps, t)
        assert state.transform_rotation[list(_rows(crowd, t))[-1]].tolist() == [0.0, 0.0, 0.0, 1.0]
        state.position[list(_rows(crowd, t))[2], 1] = np.nan
        assert not transform_data_team(m, ps, t)
    finally:
        restore(crowd, before)


# ----------------------------------------------------------------------------- E.3 triangle rotations
def _triangle_frame(model, position, tri):
    i0, i1, i2 = (int(i) for i in model.triangles[tri])
    p0 = tuple(position[i0])
    e1 = m3.v_sub(tuple(position[i1]), p0)
    e2 = m3.v_sub(tuple(position[i2]), p0)
    n = m3.v_cross(e1, e2)
    normal = m3.v_normalize(n) if m3.v_length_sq(n) > 1e-16 else (0.0, 0.0, 0.0)
    uv = model.triangle_uv[tri]
    du1, dv1 = uv[1, 0] - uv[0, 0], uv[1, 1] - uv[0, 1]
    du2, dv2 = uv[2, 0] - uv[0, 0], uv[2, 1] - uv[0, 1]
    area = du1 * dv2 - du2 * dv1
    r = 1.0 / area if area != 0.0 else 1.0
    tangent = m3.v_scale(m3.v_sub(m3.v_scale(e1, dv2), m3.v_scale(e2, dv1)), -r)
    return normal, m3.v_normalize(tangent)


def _vertex_rotation(model, frames, p, old):
    n = int(model.vertex_triangle_count[p])
    ns, ts_ = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    k0 = int(model.vertex_triangle_start[p])
    for k in range(k0, k0 + n):
        tn, tt = frames[int(model.vertex_triangle_data[k])]
        flip = int(model.vertex_triangle_flip[k])
        ns = m3.v_add(ns, m3.v_scale(tn, -1.0 if flip & 1 else 1.0))
        ts_ = m3.v_add(ts_, m3.v_scale(tt, -1.0 if flip & 2 else 1.0))
    if m3.v_length(ns) > 1e-6 and m3.v_length(ts_) > 1e-6:
        nn, tn = m3.v_normalize(ns), m3.v_normalize(ts_)
        if abs(m3.v_dot(nn, tn)) < 1.0 - 1e-9:
            return m3.q_look_rotation(m3.v_normalize(m3.v_cross(nn, tn)), nn)
    return tuple(old)


def test_triangle_rotations_give_the_scalar_bits_with_degenerate_triangles(crowd):
    m, ps, _prm, _ts, _cs, _tt, _h = crowd.kernel_tables()
    state, model = crowd.particles, crowd.model
    mesh_teams = [t for t in _teams(crowd) if model.team_triangle_count[t] > 0]
    assert mesh_teams, "the crowd's skirts are meshes"
    before = snapshot(crowd)
    try:
        t = mesh_teams[0]
        rows = list(_rows(crowd, t))
        # collapse two vertices onto a neighbour: zero-area triangles (zero normal), sums that
        # cancel, vertices left with their rotation; and a NaN-free but far-out vertex
        state.position[rows[5]] = state.position[rows[4]]
        state.position[rows[17]] = state.position[rows[16]]
        state.position[rows[30]] += (0.0, 3.0, 0.0)
        for team in mesh_teams:
            t0, tn = int(model.team_triangle_start[team]), int(model.team_triangle_count[team])
            frames = {tri: _triangle_frame(model, state.position, tri) for tri in range(t0, t0 + tn)}
            old = state.rotation.copy()
            triangle_rotations_team(m, ps, team)
            kept = 0
            for p in _rows(crowd, team):
                want = _vertex_rotation(model, frames, p, old[p])
                assert _bits(state.rotation[p]).tolist() == _bits(want).tolist(), p
                kept += int(want == tuple(old[p]))
            for tri, (tn_, tt_) in frames.items():
                assert _bits(state.triangle_normal[tri]).tolist() == _bits(tn_).tolist(), tri
                assert _bits(state.triangle_tangent[tri]).tolist() == _bits(tt_).tolist(), tri
            if team == t:
                assert kept >= 1  # the degenerate path (rotation left as it was) was taken
                zero_normals = sum(1 for tn_, _ in frames.values() if tn_ == (0.0, 0.0, 0.0))
                assert zero_normals >= 2
        assert int(model.vertex_triangle_count.max()) <= TRIANGLES_PER_VERTEX  # the strip meshes fit the slots
    finally:
        restore(crowd, before)


def test_scalar_pass_for_crowded_vertices_gives_the_vectorised_bits(crowd):
    """The pass for vertices with more than TRIANGLES_PER_VERTEX triangles, run on ordinary
    vertices, reproduces what the vectorised pass wrote."""
    m, ps, _prm, _ts, _cs, _tt, _h = crowd.kernel_tables()
    state, model = crowd.particles, crowd.model
    before = snapshot(crowd)
    try:
        team = next(t for t in _teams(crowd) if model.team_triangle_count[t] > 0)
        triangle_rotations_team(m, ps, team)
        vectorised = state.rotation.copy()
        rows = [p for p in _rows(crowd, team) if model.vertex_triangle_count[p] > 0]
        state.rotation[rows] = np.nan
        for p in rows:
            crowded_vertex_rotation(m, ps, p)
        assert (_bits(state.rotation[rows]) == _bits(vectorised[rows])).all()
    finally:
        restore(crowd, before)


# ----------------------------------------------------------------------------- E.4 write-back
def test_write_back_gives_the_scalar_formulation_bits(crowd):
    from magica_py.solver.writeback import write_transforms_team

    m, ps, _prm, _ts, _cs, _tt, _h = crowd.kernel_tables()
    state, model, h = crowd.particles, crowd.model, crowd._hierarchy
    before = snapshot(crowd)
    lp0, lq0, scale0 = h.local_position.copy(), h.local_rotation.copy(), h.lossy_scale.copy()
    try:
        h.lossy_scale[model.transform_index[1]] = (1.0, 0.0, 2.0)  # a zero scale component: 0 written
        want_p, want_q = lp0.copy(), lq0.copy()
        for t in _teams(crowd):
            assert transform_data_team(m, ps, t)
            for p in _rows(crowd, t):
                node, attr = int(model.transform_index[p]), int(model.attribute[p])
                tq = tuple(state.transform_rotation[p])
                if attr & 0x02:
                    pp = int(model.parent[p])
                    if pp < 0:
                        continue
                    iq = m3.q_inverse(tuple(state.transform_rotation[pp]))
                    lp = m3.q_rotate(iq, m3.v_sub(tuple(state.transform_position[p]), tuple(state.transform_position[pp])))
                    sc = h.lossy_scale[int(model.transform_index[pp])]
                    want_p[node] = [lp[c] / sc[c] if sc[c] != 0.0 else 0.0 for c in range(3)]
                    want_q[node] = m3.q_normalize(m3.q_mul(iq, tq))
                elif attr & 0x01:
                    parent = int(h.parent[node])
                    rot = m3.q_mul(m3.q_inverse(tuple(h.world_rotation[parent])), tq) if parent >= 0 else tq
                    want_q[node] = m3.q_normalize(rot)
            write_transforms_team(m, ps, t, h.parent, h.world_rotation, h.lossy_scale, h.local_position,
                                  h.local_rotation)
        assert (_bits(h.local_position) == _bits(want_p)).all()
        assert (_bits(h.local_rotation) == _bits(want_q)).all()
        assert (h.local_position != lp0).any(axis=1).sum() > 10   # moving bones were written
        child = [p for p in range(len(model.parent)) if model.parent[p] >= 0
                 and model.transform_index[model.parent[p]] == model.transform_index[1]]
        assert child and h.local_position[model.transform_index[child[0]], 1] == 0.0
    finally:
        h.local_position[:] = lp0
        h.local_rotation[:] = lq0
        h.lossy_scale[:] = scale0
        restore(crowd, before)


# ----------------------------------------------------------------------------- E.1 display
@pytest.mark.parametrize("time_based", [False, True])
def test_display_gives_the_scalar_formulation_bits(crowd, time_based):
    from magica_py.solver.display import MAX_DISTANCE_RATIO, display_team

    m, ps, prm, ts, _cs, _tt, _h = crowd.kernel_tables()
    state, model, params = crowd.particles, crowd.model, crowd.parameters
    before = snapshot(crowd)
    saved = params.time_based_smoothing.copy()
    dt, time, old_time, now_update = 1.0 / 90.0, 1.004, 1.0 - 1.0 / 90.0, 1.0 - 1.0 / 90.0
    try:
        params.time_based_smoothing[:] = 1 if time_based else 0
        if time_based:   # recorded step states of every history (0: none since a reset, 1, 2)
            rng = np.random.default_rng(5)
            n = state.display_local.shape[0]
            state.display_local[:] = rng.normal(0.0, 0.05, (n, 3))
            state.display_prev_local[:] = rng.normal(0.0, 0.05, (n, 3))
            state.display_history[:] = rng.integers(0, 3, n)
        for t in _teams(crowd):
            blend = float(crowd.teams.blend_weight[t])
            interval = (now_update + dt) - old_time
            frac = (time - old_time) / interval
            ahead = min(max(time - now_update, 0.0), dt)
            pos = state.position.copy()
            want_disp, want_pos = state.disp_pos.copy(), pos.copy()
            for p in _rows(crowd, t):
                pos0 = tuple(want_pos[p])
                r = int(model.root_index[p])
                if model.attribute[p] & 0x02 and time_based:
                    # quality: the recorded states in the fixed root's frame (else the team
                    # center's) at this frame's pose, interpolated at ahead / dt; no clamp
                    history = int(state.display_history[p])
                    local = tuple(state.display_local[p])
                    if history >= 2:
                        local = m3.v_lerp(tuple(state.display_prev_local[p]), local, ahead / dt)
                    if history == 0:
                        f = tuple(state.old_pos[p])
                    elif r >= 0 and not model.attribute[r] & 0x02:
                        f = m3.v_add(tuple(want_pos[r]), m3.q_rotate(tuple(state.rotation[r]), local))
                    else:
                        f = m3.v_add(tuple(crowd.teams.frame_world_pos[t]),
                                     m3.q_rotate(tuple(crowd.teams.frame_world_rot[t]), local))
                    want_disp[p] = f
                    want_pos[p] = m3.v_lerp(pos0, f, blend)
                elif model.attribute[p] & 0x02:
                    f = m3.v_add(tuple(state.old_pos[p]), m3.v_scale(tuple(state.real_velocity[p]), dt))
                    f = m3.v_lerp(tuple(state.disp_pos[p]), f, frac)
                    if r >= 0:
                        rp = tuple(want_pos[r])
                        limit = MAX_DISTANCE_RATIO * m3.v_length(m3.v_sub(rp, pos0))
                        f = m3.v_add(rp, m3.clamp_length(m3.v_sub(f, rp), limit))
                    want_disp[p] = f
                    want_pos[p] = m3.v_lerp(pos0, f, blend)
                else:
                    want_disp[p] = pos0
            display_team(m, ps, prm, ts, t, dt, time, old_time, now_update, True)
            rows = list(_rows(crowd, t))
            assert (_bits(state.disp_pos[rows]) == _bits(want_disp[rows])).all(), t
            assert (_bits(state.position[rows]) == _bits(want_pos[rows])).all(), t
            assert (_bits(state.base_pos_buffer[rows]) == _bits(pos[rows])).all(), t
            assert (_bits(state.old_position[rows]) == _bits(pos[rows])).all(), t
    finally:
        params.time_based_smoothing[:] = saved
        restore(crowd, before)
