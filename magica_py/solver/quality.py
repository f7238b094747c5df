"""Quality mode passes at the end of a step (``docs/quality-mode.md``).

MagicaCloth2's constraints are soft (docs/solver.md Appendix 4): edges stretch by 5-60 % under load and
fast particles end a step inside colliders. Quality mode adds, after the second distance pass
and the motion constraint (D.9), before the end of the step (D.10):

1. an inextensibility pass chosen by ``prm.inextensibility[team]``:

   * ``tether`` — a tight long-range attachment (Kim et al. 2012): each moving particle's
     distance to its root is clamped to its step-basic rest distance x (1 + tether_limit);
   * ``ftl`` — follow-the-leader (Mueller et al. 2012): along every baseline, root to tip,
     each edge longer than its step-basic rest length is shortened by moving the child
     only; the DFTL velocity correction gives the parent ``-s_damp x`` the child's
     correction as velocity (its reaction), so the pass does not damp the swing;
   * ``ftl_tether`` — the tether, then FTL (edges exact, root distance bounded);
   * ``iterations`` — ``distance_iterations`` more D.4 passes (the brute-force candidate);
   * ``ftl_edges`` — ``distance_iterations`` Gauss-Seidel passes of a unilateral PBD
     projection over every proxy edge (horizontal skirt edges too, depth-weighted masses as
     D.4, fixed ends immovable), then the tether and FTL;

2. ``collision_last``: a final point projection of every colliding particle against each
   collider in turn, so that no particle ends the step inside one.

Every pass is unilateral (only stretch is removed) and uses the step-basic pose (D.2) as the
rest reference, like the tether of D.3. Faithful mode never calls this module.
"""
from __future__ import annotations


from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, load3, store3, v_add, v_dot, v_length, v_lerp, v_mul, v_scale, v_sub,
)
from magica_py.solver.constraints.collision import (
    INVALID_OR_NO_COLLISION, PLANE, SPHERE, segment_parameter, solve_point_collider,
)
from magica_py.solver.constraints.distance import distance_team
from magica_py.solver.parameters import curve_at
from magica_py.kernels import portable

MOVE = 0x02
INEXT_NONE = 0
INEXT_TETHER = 1
INEXT_FTL = 2
INEXT_FTL_TETHER = 3
INEXT_ITERATIONS = 4
INEXT_FTL_EDGES = 5
INSIDE_TOLERANCE = 1e-6   # m


@kernel
def clamp_to_sphere(x, center, radius):
    """``x`` moved onto the sphere (center, radius) when it lies outside it; and the move."""
    v = v_sub(x, center)
    length = v_length(v)
    if length <= radius or length < 1e-12:
        return x, (0.0, 0.0, 0.0)
    target = v_add(center, v_scale(v, radius / length))
    return target, v_sub(target, x)


@kernel
def tight_tether_team(m, ps, prm, team):
    """Root distance of every moving particle <= step-basic rest x (1 + tether_limit).
    The correction becomes velocity in full (plain PBD)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_root_index, m_team_particle_count = m.attribute, m.root_index, m.team_particle_count
    ps_next_pos, ps_step_basic_pos = ps.next_pos, ps.step_basic_pos
    limit = 1.0 + prm.tether_limit[team]
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        if (m_attribute[p] & MOVE) == 0:
            continue
        r = m_root_index[p]
        if r < 0:
            continue
        rest = v_length(v_sub(load3(ps_step_basic_pos, p), load3(ps_step_basic_pos, r)))
        x, _move = clamp_to_sphere(load3(ps_next_pos, p), load3(ps_next_pos, r), rest * limit)
        store3(ps_next_pos, p, x)


@kernel
def ftl_team(m, ps, prm, team):
    """Follow-the-leader along each baseline (parents before children): every edge is at
    most its step-basic rest length. DFTL: the parent's velocity gets ``-s_damp`` x the
    child's correction (velocity_pos += s_damp x correction)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_baseline_count, m_baseline_data = m.attribute, m.baseline_count, m.baseline_data
    m_baseline_start, m_parent, m_team_baseline_count = m.baseline_start, m.parent, m.team_baseline_count
    ps_next_pos, ps_step_basic_pos, ps_velocity_pos = ps.next_pos, ps.step_basic_pos, ps.velocity_pos
    damping = prm.ftl_damping[team]
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m_team_baseline_count[team]):
        e0 = m_baseline_start[b]
        for e in range(e0 + 1, e0 + m_baseline_count[b]):
            v = m_baseline_data[e]
            if (m_attribute[v] & MOVE) == 0:
                continue
            p = m_parent[v]
            if p < 0:
                continue
            rest = v_length(v_sub(load3(ps_step_basic_pos, v), load3(ps_step_basic_pos, p)))
            x, move = clamp_to_sphere(load3(ps_next_pos, v), load3(ps_next_pos, p), rest)
            store3(ps_next_pos, v, x)
            if damping > 0.0 and (m_attribute[p] & MOVE) != 0:
                store3(ps_velocity_pos, p, v_add(load3(ps_velocity_pos, p), v_scale(move, damping)))


@kernel
def edge_pass_team(m, ps, team):
    """One Gauss-Seidel pass of unilateral edge projection over the team's proxy edges:
    an edge longer than its step-basic rest length is shortened, both ends moving in
    proportion to their inverse masses (D.4's depth masses; fixed ends do not move).
    Corrections become velocity in full."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_depth, m_edges, m_team_edge_count = m.attribute, m.depth, m.edges, m.team_edge_count
    ps_friction, ps_next_pos, ps_step_basic_pos = ps.friction, ps.next_pos, ps.step_basic_pos
    e0 = m.team_edge_start[team]
    for e in range(e0, e0 + m_team_edge_count[team]):
        a = m_edges[e, 0]
        b = m_edges[e, 1]
        wa = inverse_mass_friction_depth(ps_friction[a], m_depth[a]) if (m_attribute[a] & MOVE) != 0 else 0.0
        wb = inverse_mass_friction_depth(ps_friction[b], m_depth[b]) if (m_attribute[b] & MOVE) != 0 else 0.0
        if wa + wb <= 0.0:
            continue
        rest = v_length(v_sub(load3(ps_step_basic_pos, a), load3(ps_step_basic_pos, b)))
        pa = load3(ps_next_pos, a)
        pb = load3(ps_next_pos, b)
        d = v_sub(pb, pa)
        length = v_length(d)
        if length <= rest or length < 1e-12:
            continue
        c = v_scale(d, (length - rest) / (length * (wa + wb)))
        store3(ps_next_pos, a, v_add(pa, v_scale(c, wa)))
        store3(ps_next_pos, b, v_sub(pb, v_scale(c, wb)))


@kernel
def display_ftl_team(m, ps, ts, team):
    """Quality display: the extrapolated display positions (``ps.position``) go through one
    FTL pass so that extrapolating each particle along its own velocity does not stretch
    the edges the step kept. Rest length: the larger of the last step's (step-basic pose)
    and the build rest length at the current scale (the step-basic pose is not set before
    the first step, e.g. a first frame at 240 fps runs no 90 Hz step)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_baseline_count, m_baseline_data = m.attribute, m.baseline_count, m.baseline_data
    m_baseline_local_position, m_baseline_start = m.baseline_local_position, m.baseline_start
    m_parent, m_team_baseline_count, ps_position = m.parent, m.team_baseline_count, ps.position
    ps_step_basic_pos = ps.step_basic_pos
    s = v_scale(load3(m.team_init_scale, team), ts.scale_ratio[team])
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m_team_baseline_count[team]):
        e0 = m_baseline_start[b]
        for e in range(e0 + 1, e0 + m_baseline_count[b]):
            v = m_baseline_data[e]
            p = m_parent[v]
            if (m_attribute[v] & MOVE) == 0 or p < 0:
                continue
            rest = max(v_length(v_sub(load3(ps_step_basic_pos, v), load3(ps_step_basic_pos, p))),
                       v_length(v_mul(load3(m_baseline_local_position, v), s)))
            x, _move = clamp_to_sphere(load3(ps_position, v), load3(ps_position, p), rest)
            store3(ps_position, v, x)


@kernel
def collision_last_team(m, ps, prm, ts, cs, team):
    """Project every colliding moving particle out of each collider in turn (point test of
    D.8 with the particle radius; friction and normals are left to D.8)."""
    project_out_of_colliders(m, prm, ts, cs, team, ps.next_pos, ps.old_pos)


@kernel
def display_collision_team(m, ps, prm, ts, cs, team):
    """Quality display: the extrapolated display positions projected out of the colliders
    (at their pose of the last step), so that extrapolating does not show a particle inside."""
    project_out_of_colliders(m, prm, ts, cs, team, ps.position, ps.old_pos)


@kernel
def inside_old_pose(cs, k, x, r):
    """Is x (with radius r) deeper than ``INSIDE_TOLERANCE`` inside collider slot k at its
    previous-step pose? (A particle projected by the last step lies on the surface.)"""
    shape = cs.shape[k]
    so = load3(cs.start_old, k)
    reach = r - INSIDE_TOLERANCE
    if shape == PLANE:
        return v_dot(v_sub(x, so), load3(cs.plane_normal, k)) < reach
    if shape == SPHERE:
        return v_length(v_sub(x, so)) < cs.radius_start[k] + reach
    eo = load3(cs.end_old, k)
    t = segment_parameter(x, so, eo)
    radius = cs.radius_start[k] + (cs.radius_end[k] - cs.radius_start[k]) * t
    return v_length(v_sub(x, v_lerp(so, eo, t))) < radius + reach


@kernel
def project_out_of_colliders(m, prm, ts, cs, team, positions, ps_old_pos):
    """Point projection of ``positions`` (N, 3) of the team's colliding moving particles.

    A particle whose last step ended inside the collider too (``old_pos``: a collider that
    appeared around the cloth, e.g. the engulfing hard case) is left to D.8 and the distance
    pass: projecting every such particle to the surface at once would tear the chain across
    the collider (81 % edge stretch in the engulfing case, 0 % this way). Once out, a
    particle is kept out."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_scale_suspend, m_attribute, m_depth = cs.scale_suspend, m.attribute, m.depth
    m_team_particle_count, prm_radius_curve = m.team_particle_count, prm.radius_curve
    scale = ts.scale_ratio[team]
    c0 = ts.collider_start[team]
    c1 = c0 + ts.collider_count[team]
    start = m.team_particle_start[team]
    for p in range(start, start + m_team_particle_count[team]):
        attr = m_attribute[p]
        if (attr & MOVE) == 0 or (attr & INVALID_OR_NO_COLLISION) != 0:
            continue
        r = max(curve_at(prm_radius_curve, team, m_depth[p]), 0.0001) * scale
        x = load3(positions, p)
        for k in range(c0, c1):
            if cs_scale_suspend[k] != 0:
                continue
            bmin = (x[0] - 2.0 * r, x[1] - 2.0 * r, x[2] - 2.0 * r)
            bmax = (x[0] + 2.0 * r, x[1] + 2.0 * r, x[2] + 2.0 * r)
            d, _n, x2 = solve_point_collider(cs, k, x, r, bmin, bmax)
            if d < 0.0:
                if not inside_old_pose(cs, k, load3(ps_old_pos, p), r):
                    x = x2
        store3(positions, p, x)


@kernel
def quality_distance_attenuation(prm, team, faithful_attenuation):
    """D.4's velocity attenuation: 0 (full PBD velocity) when distance_full_velocity is on."""
    if prm.distance_full_velocity[team] != 0:
        return 0.0
    return faithful_attenuation


@kernel
def quality_hard_attenuation(prm, team, frequency_ratio, attenuation, converted):
    """Velocity attenuation of a hard limit (tether D.3, angle limit D.5, motion D.9) at the
    step size. When a limit removes a step's penetration, ``1 - attn`` of the normal velocity
    survives into the next step: a per-step retention, so quality mode converts it as one,
    ``attn^(90/f)`` (the frequency-consistent mode converts attn as a rate, which lets the
    surviving share tend to 1 - and the limit to a hard bounce - as f grows)."""
    if prm.quality[team] == 0:
        return converted
    return portable.pow(attenuation, frequency_ratio)


@kernel
def quality_restoration_attenuation(prm, team, frequency_ratio, converted):
    """D.6's velocity attenuation at the step size. Quality mode scales the share of the
    restoration correction that becomes velocity, ``1 - attn``, linearly with the step
    (``(1 - attn) 90/f``): the correction itself is about proportional to the step, so the
    velocity it leaves per unit time stays the same at any frequency (the converted rate of
    the frequency-consistent mode lets that share tend to 1 as f grows, and the restoration
    then acts as a force growing with f: 29 % of the tail's length between 90 and 1440 Hz)."""
    if prm.quality[team] == 0:
        return converted
    share = (1.0 - prm.restoration_attenuation[team]) * frequency_ratio
    return 1.0 - (1.0 if share > 1.0 else (0.0 if share < 0.0 else share))


@kernel
def quality_end_of_step(m, ps, prm, ts, cs, team, frequency_ratio, power_y, distance_attenuation):
    """The quality passes of one team after D.9 (see the module docstring)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    prm_distance_iterations = prm.distance_iterations
    mode = prm.inextensibility[team]
    if mode == INEXT_FTL_EDGES:
        for _ in range(prm_distance_iterations[team]):
            edge_pass_team(m, ps, team)
    if mode == INEXT_TETHER or mode == INEXT_FTL_TETHER or mode == INEXT_FTL_EDGES:
        tight_tether_team(m, ps, prm, team)
    if mode == INEXT_FTL or mode == INEXT_FTL_TETHER or mode == INEXT_FTL_EDGES:
        ftl_team(m, ps, prm, team)
    elif mode == INEXT_ITERATIONS:
        for _ in range(prm_distance_iterations[team]):
            distance_team(m, ps, prm, ts, team, frequency_ratio, power_y, distance_attenuation)
    if prm.collision_last[team] != 0 and ts.collider_count[team] > 0 and prm.collision_mode[team] != 0:
        collision_last_team(m, ps, prm, ts, cs, team)
