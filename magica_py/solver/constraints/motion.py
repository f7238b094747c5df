"""Motion constraint (docs/solver.md §D.9): max distance from the animated pose and a backstop sphere
behind it. The reference is always the animated ``base_pos``; distances are not scaled and the
curves are evaluated at depth^2.

``motion_block`` runs one block through the per-element function ``solve_motion``, every lane
side by side."""
from __future__ import annotations


from magica_py.build.proxy import INVALID_MOTION, MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import q_rotate, v_add, v_length, v_lerp, v_scale, v_sub
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.constraints.collision import particle_radius
from magica_py.solver.lanes import get1, get3, get4, put3
from magica_py.solver.parameters import (
    PRM_BACKSTOP_RADIUS, PRM_MOTION_STIFFNESS, PRM_NORMAL_AXIS,
    PRM_USE_BACKSTOP, PRM_USE_MAX_DISTANCE,
)

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
    shortened vector is computed either way and selected."""
    n = v_length(v)
    shortened = v_scale(v, max_length / max(n, 1e-300))   # a zero vector: discarded below
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


@kernel(forceinline=False)
def motion_block(PS, PP, TS, P, BI, topology, b, attenuation):
    """D.9 over block b's moving particles (skipped when the block uses neither limit), every
    lane side by side; the move is added to ``velocity_pos`` times ``attenuation``."""
    use_max = P[b, PRM_USE_MAX_DISTANCE] != 0.0
    use_backstop = P[b, PRM_USE_BACKSTOP] != 0.0
    if not use_max and not use_backstop:
        return
    axis = normal_axis_vector(int(P[b, PRM_NORMAL_AXIS]))
    backstop_radius = P[b, PRM_BACKSTOP_RADIUS]
    stiffness = P[b, PRM_MOTION_STIFFNESS]
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    for j in range(BI[b, bk.BI_N]):
        attr = topology[attribute + j]
        if (attr & MOVE) == 0 or (attr & INVALID_MOTION) != 0:
            continue
        g = g0 + j
        for l in range(w):
            unit = get1(TS, b, st.LENGTH_UNIT, l)   # 1.0 in faithful mode (the reference does not scale them)
            r = particle_radius(get1(PP, g, bk.CURVE_RADIUS, l), unit)
            direction = q_rotate(get4(PS, g, st.BASE_ROT, l), axis)
            o = get3(PS, g, st.NEXT_POS, l)
            x = solve_motion(o, get3(PS, g, st.BASE_POS, l), direction,
                             get1(PP, g, bk.CURVE_MAX_DISTANCE, l) * unit, use_max, use_backstop,
                             get1(PP, g, bk.CURVE_BACKSTOP_DISTANCE, l) * unit, backstop_radius * unit,
                             r, stiffness)
            put3(PS, g, st.NEXT_POS, l, x)
            put3(PS, g, st.VELOCITY_POS, l, v_add(get3(PS, g, st.VELOCITY_POS, l), v_scale(v_sub(x, o), attenuation)))
