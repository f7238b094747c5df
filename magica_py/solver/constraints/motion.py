"""Motion constraint (docs/solver.md §D.9): max distance from the animated pose and a backstop sphere
behind it. The reference is always the animated ``base_pos``; distances are not scaled and the
curves are evaluated at depth^2.

``motion_team`` runs one team; ``motion_block`` runs every lane of a block
(``solver/batched``) with the same per-element function ``solve_motion``, so both give the
same bits."""
from __future__ import annotations

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, q_rotate, store3, v_add, v_length, v_lerp, v_scale, v_sub
from magica_py.kernels.streams import READ, open_streams, sload3, sload4, sstore3
from magica_py.solver.parameters import curve_at, length_unit

MOVE = 0x02
INVALID_MOTION = 0x08
VELOCITY_ATTENUATION = 0.95


@kernel
def normal_axis_vector(axis):
    if axis == 0:
        return (1.0, 0.0, 0.0)
    if axis == 1:
        return (0.0, 1.0, 0.0)
    if axis == 2:
        return (0.0, 0.0, 1.0)
    if axis == 3:
        return (-1.0, 0.0, 0.0)
    if axis == 4:
        return (0.0, -1.0, 0.0)
    return (0.0, 0.0, -1.0)


@kernel
def clamp_length_selected(v, max_length):
    """``math3d.clamp_length`` (``clamp_len`` of §0.2) with the same bits, branch-free: the
    shortened vector is computed either way and selected, so a lane loop over it vectorises."""
    n = v_length(v)
    shortened = v_scale(v, max_length / n)
    return shortened if (n > 1e-9) & (n > max_length) else v


@kernel
def solve_motion(x, base_pos, direction, max_distance, use_max, use_backstop,
                 backstop_distance, backstop_radius, particle_radius, stiffness):
    """The constrained position of x blended by ``stiffness``: clamped to ``max_distance`` of
    the animated position (``use_max``), then pushed out of the backstop sphere behind it
    (``use_backstop``). Branch-free (every side computed, then selected)."""
    o = x
    clamped = v_add(base_pos, clamp_length_selected(v_sub(x, base_pos), max_distance))
    x = clamped if use_max else x
    c = v_sub(base_pos, v_scale(direction, backstop_distance + backstop_radius))
    v = v_sub(x, c)
    length = v_length(v)
    pushed = v_add(c, v_scale(v, backstop_radius / length))
    inside = ((length > 1e-8) & (length < backstop_radius + particle_radius) & (length < backstop_radius))
    x = pushed if (use_backstop & (backstop_radius > 0.0) & inside) else x
    return v_lerp(o, x, stiffness)


@kernel
def motion_team(m, ps, prm, team, attenuation):
    """D.9 over one team's moving particles (skipped when the team uses neither limit)."""
    use_max = prm.use_max_distance[team] != 0
    use_backstop = prm.use_backstop[team] != 0
    if not use_max and not use_backstop:
        return
    axis = normal_axis_vector(prm.normal_axis[team])
    unit = length_unit(m, prm, team)   # 1.0 in faithful mode (the reference does not scale them)
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        attr = m.attribute[p]
        if (attr & MOVE) == 0 or (attr & INVALID_MOTION) != 0:
            continue
        d2 = m.depth[p] * m.depth[p]
        r = max(curve_at(prm.radius_curve, team, m.depth[p]), 1e-4) * unit
        direction = q_rotate(load4(ps.base_rot, p), axis)
        o = load3(ps.next_pos, p)
        x = solve_motion(o, load3(ps.base_pos, p), direction,
                         curve_at(prm.max_distance_curve, team, d2) * unit, use_max, use_backstop,
                         curve_at(prm.backstop_distance_curve, team, d2) * unit, prm.backstop_radius[team] * unit,
                         r, prm.motion_stiffness[team])
        store3(ps.next_pos, p, x)
        store3(ps.velocity_pos, p, v_add(load3(ps.velocity_pos, p), v_scale(v_sub(x, o), attenuation)))


@kernel
def motion_block(m, bs, prm, blk, b, attenuation):
    """D.9 for every lane of block b: ``motion_team``'s maths, lanes innermost (the curves
    are read per particle, outside the lane loop).

    Lane streams (``kernels/streams``): the loop updates next_pos (1-3) and velocity_pos (4-6)
    of the particle's rows in place; the animated pose is only read."""
    ex = blk.block_exemplar[b]
    use_max = prm.use_max_distance[ex] != 0
    use_backstop = prm.use_backstop[ex] != 0
    if not use_max and not use_backstop:
        return
    axis = normal_axis_vector(prm.normal_axis[ex])
    width = blk.block_width[b]
    row_base = blk.block_row_base[b]
    p0 = m.team_particle_start[ex]
    backstop_radius = prm.backstop_radius[ex]
    stiffness = prm.motion_stiffness[ex]
    next_pos_a, velocity_pos_a, base_pos_a, base_rot_a = bs.next_pos, bs.velocity_pos, bs.base_pos, bs.base_rot
    for p in range(blk.block_particle_count[b]):
        attr = m.attribute[p0 + p]
        if (attr & MOVE) == 0 or (attr & INVALID_MOTION) != 0:
            continue
        depth = m.depth[p0 + p]
        d2 = depth * depth
        r = max(curve_at(prm.radius_curve, ex, depth), 1e-4)
        max_distance = curve_at(prm.max_distance_curve, ex, d2)
        backstop_distance = curve_at(prm.backstop_distance_curve, ex, d2)
        k0 = np.uint64(row_base + p * width)
        open_streams()
        for i in range(width):
            k = k0 + np.uint64(i)
            direction = q_rotate(sload4(base_rot_a, k, READ), axis)
            o = sload3(next_pos_a, k, 1)
            x = solve_motion(o, sload3(base_pos_a, k, READ), direction, max_distance, use_max, use_backstop,
                             backstop_distance, backstop_radius, r, stiffness)
            sstore3(next_pos_a, k, x, 1)
            sstore3(velocity_pos_a, k, v_add(sload3(velocity_pos_a, k, 4), v_scale(v_sub(x, o), attenuation)), 4)
