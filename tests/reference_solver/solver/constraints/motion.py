"""Motion constraint (docs/solver.md §D.9): max distance from the animated pose and a backstop sphere
behind it. The reference is always the animated ``base_pos``; distances are not scaled and the
curves are evaluated at depth^2.

``motion_team`` runs one team through the per-element function ``solve_motion``."""
from __future__ import annotations


from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, q_rotate, store3, v_add, v_length, v_lerp, v_scale, v_sub
from reference_solver.solver.constraints.collision import particle_radius
from reference_solver.solver.parameters import curve_at, length_unit

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


@kernel
def motion_team(m, ps, prm, team, attenuation):
    """D.9 over one team's moving particles (skipped when the team uses neither limit)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_depth, m_team_particle_count = m.attribute, m.depth, m.team_particle_count
    prm_backstop_distance_curve, prm_backstop_radius = prm.backstop_distance_curve, prm.backstop_radius
    prm_max_distance_curve, prm_motion_stiffness = prm.max_distance_curve, prm.motion_stiffness
    prm_radius_curve, ps_base_pos, ps_base_rot = prm.radius_curve, ps.base_pos, ps.base_rot
    ps_next_pos, ps_velocity_pos = ps.next_pos, ps.velocity_pos
    use_max = prm.use_max_distance[team] != 0
    use_backstop = prm.use_backstop[team] != 0
    if not use_max and not use_backstop:
        return
    axis = normal_axis_vector(prm.normal_axis[team])
    unit = length_unit(m, prm, team)   # 1.0 in faithful mode (the reference does not scale them)
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        attr = m_attribute[p]
        if (attr & MOVE) == 0 or (attr & INVALID_MOTION) != 0:
            continue
        d2 = m_depth[p] * m_depth[p]
        r = particle_radius(prm_radius_curve, team, m_depth[p], unit)
        direction = q_rotate(load4(ps_base_rot, p), axis)
        o = load3(ps_next_pos, p)
        x = solve_motion(o, load3(ps_base_pos, p), direction,
                         curve_at(prm_max_distance_curve, team, d2) * unit, use_max, use_backstop,
                         curve_at(prm_backstop_distance_curve, team, d2) * unit, prm_backstop_radius[team] * unit,
                         r, prm_motion_stiffness[team])
        store3(ps_next_pos, p, x)
        store3(ps_velocity_pos, p, v_add(load3(ps_velocity_pos, p), v_scale(v_sub(x, o), attenuation)))


