"""Motion constraint (ref §D.9): max distance from the animated pose and a backstop sphere
behind it. The reference is always the animated ``base_pos``; distances are not scaled and the
curves are evaluated at depth^2."""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    clamp_length, load3, load4, q_rotate, store3, v_add, v_length, v_lerp, v_scale, v_sub,
)
from magica_py.solver.parameters import curve_at

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
def solve_motion(x, base_pos, direction, max_distance, use_max, use_backstop,
                 backstop_distance, backstop_radius, particle_radius, stiffness):
    """Return the constrained position of x (before the stiffness blend is applied by the caller)."""
    o = x
    if use_max:
        x = v_add(base_pos, clamp_length(v_sub(x, base_pos), max_distance))
    if use_backstop and backstop_radius > 0.0:
        c = v_sub(base_pos, v_scale(direction, backstop_distance + backstop_radius))
        v = v_sub(x, c)
        length = v_length(v)
        if length > 1e-8 and length < backstop_radius + particle_radius and length < backstop_radius:
            x = v_add(c, v_scale(v, backstop_radius / length))
    return v_lerp(o, x, stiffness)


@kernel
def motion_team(m, ps, prm, team, attenuation):
    use_max = prm.use_max_distance[team] != 0
    use_backstop = prm.use_backstop[team] != 0
    if not use_max and not use_backstop:
        return
    axis = normal_axis_vector(prm.normal_axis[team])
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        attr = m.attribute[p]
        if (attr & MOVE) == 0 or (attr & INVALID_MOTION) != 0:
            continue
        d2 = m.depth[p] * m.depth[p]
        r = max(curve_at(prm.radius_curve, team, m.depth[p]), 1e-4)
        direction = q_rotate(load4(ps.base_rot, p), axis)
        o = load3(ps.next_pos, p)
        x = solve_motion(o, load3(ps.base_pos, p), direction,
                         curve_at(prm.max_distance_curve, team, d2), use_max, use_backstop,
                         curve_at(prm.backstop_distance_curve, team, d2), prm.backstop_radius[team],
                         r, prm.motion_stiffness[team])
        store3(ps.next_pos, p, x)
        store3(ps.velocity_pos, p, v_add(load3(ps.velocity_pos, p), v_scale(v_sub(x, o), attenuation)))
