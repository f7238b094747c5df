"""Quality mode's display (``docs/quality-mode.md``, *Display*): after E.1 (``display.py``) the
interpolated display is moved towards a target that is out of the colliders at this frame's
pose, never showing an edge longer than the step states it interpolates allow
(``display_constraints_team``). The step passes are in ``quality.py``.
"""
from __future__ import annotations

import math

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    load3, load4, q_rotate, store3, v_add, v_dot, v_length, v_length_sq, v_lerp, v_scale, v_sub,
)
from reference_solver.solver.colliders import capsule_ends
from reference_solver.solver.constraints.collision import (
    INVALID_OR_NO_COLLISION, PLANE, SPHERE, particle_radius, segment_parameter,
)
from reference_solver.solver.parameters import length_unit
from reference_solver.solver.quality import MOVE, clamp_to_sphere, push_out_of_ball

DISPLAY_PASSES = 2        # collider push + edge clamp passes of the quality display
DISPLAY_EDGE_PASSES = 2    # edge passes of the quality display's target after its collider push
DISPLAY_MOVE_PASSES = 3    # bounded moves of the quality display towards its target


@kernel
def frame_collider_push(cs, k, x, r):
    """``x`` (a sphere of radius r) moved onto the surface of collider slot k at this frame's
    pose (G.2: ``frame_pos`` / ``frame_rot`` / ``frame_scale``) when it lies inside it, along
    the shortest way out; unchanged otherwise (or when its centre is on the capsule's axis)."""
    shape = cs.shape[k]
    pos = load3(cs.frame_pos, k)
    rot = load4(cs.frame_rot, k)
    if shape == PLANE:
        n = q_rotate(rot, (0.0, -1.0 if cs.frame_scale[k, 1] < 0.0 else 1.0, 0.0))
        d = v_dot(v_sub(x, pos), n) - r
        return v_sub(x, v_scale(n, d)) if d < 0.0 else x
    if shape == SPHERE:
        a = pos
        b = pos
        ra = cs.size[k, 0] * abs(cs.frame_scale[k, 0])
        rb = ra
    else:
        d = cs.direction[k]
        size = (cs.size[k, 0], cs.size[k, 1], cs.size[k, 2])
        a, b, ra, rb = capsule_ends(pos, rot, d, cs.reverse_direction[k] != 0, cs.aligned_on_center[k] != 0,
                                    size, cs.frame_scale[k, d])
    t = segment_parameter(x, a, b)
    c = v_lerp(a, b, t)
    reach = ra + (rb - ra) * t + r
    return push_out_of_ball(x, c, reach)


@kernel
def frame_collider_push_bounded(cs, k, x, r, parent, bound):
    """``frame_collider_push`` of x, kept within ``bound`` of ``parent`` when it can be: a
    pushed point farther than ``bound`` from ``parent`` is moved to the nearest point of the
    circle where the pushed-to surface (the sphere, or a capsule's sphere at the pushed
    point's axis parameter) meets the sphere of radius ``bound`` around ``parent``; exact for a
    sphere, where alternating the push with the parent clamp only converges slowly. Where that
    circle does not exist (the parent deeper than ``bound``, or a plane) the pushed point is
    returned and the caller's clamp wins."""
    y = frame_collider_push(cs, k, x, r)
    if cs.shape[k] == PLANE or (y[0] == x[0] and y[1] == x[1] and y[2] == x[2]):
        return y
    if v_length_sq(v_sub(y, parent)) <= bound * bound:
        return y
    pos = load3(cs.frame_pos, k)
    if cs.shape[k] == SPHERE:
        c = pos
        reach = cs.size[k, 0] * abs(cs.frame_scale[k, 0]) + r
    else:
        d = cs.direction[k]
        size = (cs.size[k, 0], cs.size[k, 1], cs.size[k, 2])
        a, b, ra, rb = capsule_ends(pos, load4(cs.frame_rot, k), d, cs.reverse_direction[k] != 0,
                                    cs.aligned_on_center[k] != 0, size, cs.frame_scale[k, d])
        t = segment_parameter(x, a, b)
        c = v_lerp(a, b, t)
        reach = ra + (rb - ra) * t + r
    n = v_sub(parent, c)
    dist = v_length(n)
    if dist < 1e-12:
        return y
    n = v_scale(n, 1.0 / dist)
    along = (reach * reach - bound * bound + dist * dist) / (2.0 * dist)   # circle plane, from c along n
    h2 = reach * reach - along * along
    if h2 <= 0.0:
        return y
    w = v_sub(y, c)
    w = v_sub(w, v_scale(n, v_dot(w, n)))
    wl = v_length(w)
    if wl < 1e-12:
        return y
    return v_add(v_add(c, v_scale(n, along)), v_scale(w, math.sqrt(h2) / wl))


@kernel
def display_edge_bound(ps, a, b, dt):
    """The longest the displayed edge (a, b) may be: the larger of its step-basic rest length
    and its length in the two step states the display interpolates, the last one
    (``old_pos``) and the one before (``old_pos - real_velocity dt``, D.10's definition of the
    real velocity; the C.5 shift moves and turns both together)."""
    old_a = load3(ps.old_pos, a)
    old_b = load3(ps.old_pos, b)
    before = v_sub(v_sub(old_a, v_scale(load3(ps.real_velocity, a), dt)),
                   v_sub(old_b, v_scale(load3(ps.real_velocity, b), dt)))
    rest = v_length(v_sub(load3(ps.step_basic_pos, a), load3(ps.step_basic_pos, b)))
    return max(rest, max(v_length(v_sub(old_a, old_b)), v_length(before)))


@kernel
def safe_fraction(e0, de, bound):
    """The largest s in [0, 1] with |e0 + s de| <= max(bound, |e0|) (|.| is convex in s, so
    every s below it keeps the edge within the bound too)."""
    limit = max(bound, v_length(e0))
    end = v_add(e0, de)
    if v_dot(end, end) <= limit * limit:
        return 1.0
    a = v_dot(de, de)
    half_b = v_dot(e0, de)
    c = v_dot(e0, e0) - limit * limit
    disc = half_b * half_b - a * c
    if a <= 0.0 or disc <= 0.0:
        return 0.0
    return min(max((-half_b + math.sqrt(disc)) / a, 0.0), 1.0)


@kernel
def display_constraints_team(m, ps, prm, ts, cs, team, dt):
    """Quality display after E.1 (``display.display_team``): the interpolated display in
    ``ps.position`` (every edge within its bound, ``display_edge_bound``) moved towards a
    target that is out of the colliders at this frame's pose, never past the bounds.

    1. The target, in ``ps.position``: along every baseline, parents first, each Move
       particle is pushed out of the team's colliders at this frame's pose, onto the
       nearest point that is also within its parent link's bound when there is one
       (``frame_collider_push_bounded``; only when the cloth collides: ``collision_mode`` not
       none and ``collision_last`` on), and kept within that bound (follow-the-leader),
       ``DISPLAY_PASSES`` times; then ``DISPLAY_EDGE_PASSES`` Gauss-Seidel passes shorten the
       other edges (a skirt's rings) longer than their bound, both ends moving.
    2. The display, in ``ps.disp_pos``: starting from the interpolated display, the whole
       team moves towards its target by one common fraction, the largest that keeps every
       link (D.4's partners, every proxy edge) within its bound (each link moves linearly in
       the fraction and its length is convex, ``safe_fraction``): a target within every
       bound (a line cloth's) is reached exactly. Then each Move particle in turn moves
       towards its target by the largest fraction that keeps each of its links within its
       bound with its neighbours' current display, ``DISPLAY_MOVE_PASSES`` times. Every move
       keeps the display within the bounds, so none is ever shown longer than the state
       allows; where a push would need more stretch than the state has, the particle is
       shown partly inside the collider. Then copied to ``ps.position``."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_scale_suspend, m_attribute, m_baseline_count = cs.scale_suspend, m.attribute, m.baseline_count
    m_baseline_data, m_baseline_start, m_depth = m.baseline_data, m.baseline_start, m.depth
    m_distance_count, m_distance_start = m.distance_count, m.distance_start
    m_distance_target, m_edges, m_parent = m.distance_target, m.edges, m.parent
    m_team_baseline_count, prm_radius_curve, ps_disp_pos = m.team_baseline_count, prm.radius_curve, ps.disp_pos
    ps_position = ps.position
    blend = ts.blend_weight[team]
    start = m.team_particle_start[team]
    end = start + m.team_particle_count[team]
    for p in range(start, end):   # the interpolated display, blended (E.1)
        store3(ps_disp_pos, p, load3(ps_position, p))
    if blend <= 0.0:
        return
    collide = prm.collision_mode[team] != 0 and prm.collision_last[team] != 0 and ts.collider_count[team] > 0
    scale = ts.scale_ratio[team] * length_unit(m, prm, team)
    c0 = ts.collider_start[team]
    c1 = c0 + ts.collider_count[team]
    b0 = m.team_baseline_start[team]
    for bl in range(b0, b0 + m_team_baseline_count[team]):
        e0 = m_baseline_start[bl]
        for e in range(e0 + 1, e0 + m_baseline_count[bl]):
            v = m_baseline_data[e]
            p = m_parent[v]
            attr = m_attribute[v]
            if (attr & MOVE) == 0 or p < 0:
                continue
            bound = display_edge_bound(ps, v, p, dt)
            parent_pos = load3(ps_position, p)
            x0 = load3(ps_position, v)
            x = x0
            hits = collide and (attr & INVALID_OR_NO_COLLISION) == 0
            r = particle_radius(prm_radius_curve, team, m_depth[v], scale)
            for _ in range(DISPLAY_PASSES):
                if hits:
                    for k in range(c0, c1):
                        if cs_scale_suspend[k] == 0:
                            x = frame_collider_push_bounded(cs, k, x, r, parent_pos, bound)
                x, _move = clamp_to_sphere(x, parent_pos, bound)
            store3(ps_position, v, x)
    f0 = m.team_edge_start[team]
    f1 = f0 + m.team_edge_count[team]
    for _ in range(DISPLAY_EDGE_PASSES):
        for f in range(f0, f1):
            a = m_edges[f, 0]
            b = m_edges[f, 1]
            wa = 1.0 if (m_attribute[a] & MOVE) != 0 else 0.0
            wb = 1.0 if (m_attribute[b] & MOVE) != 0 else 0.0
            if wa + wb <= 0.0:
                continue
            pa = load3(ps_position, a)
            pb = load3(ps_position, b)
            d = v_sub(pb, pa)
            length = v_length(d)
            bound = display_edge_bound(ps, a, b, dt)
            if length <= bound or length < 1e-12:
                continue
            c = v_scale(d, (length - bound) / (length * (wa + wb)))
            store3(ps_position, a, v_add(pa, v_scale(c, wa)))
            store3(ps_position, b, v_sub(pb, v_scale(c, wb)))
    # the whole team towards its target by one fraction: each edge moves linearly in it (an edge
    # is seen from its moving ends, as in the passes below; one whose ends keep still keeps its length)
    common = 1.0
    moved = False
    for v in range(start, end):
        shown = load3(ps_disp_pos, v)
        target = load3(ps_position, v)
        move_v = v_sub(target, shown)
        if (m_attribute[v] & MOVE) == 0 or v_dot(move_v, move_v) == 0.0:
            continue
        moved = True
        for link in range(m_distance_start[v], m_distance_start[v] + m_distance_count[v]):
            u = m_distance_target[link]
            e0 = v_sub(shown, load3(ps_disp_pos, u))
            e1 = v_sub(target, load3(ps_position, u))
            if v_dot(e1, e1) > v_dot(e0, e0):   # otherwise the edge never gets longer than now
                common = min(common, safe_fraction(e0, v_sub(e1, e0), display_edge_bound(ps, v, u, dt)))
    if not moved:
        return   # the target is the interpolated display (already in ps.position)
    if common > 0.0:
        for v in range(start, end):
            if (m_attribute[v] & MOVE) != 0:
                shown = load3(ps_disp_pos, v)
                store3(ps_disp_pos, v, v_add(shown, v_scale(v_sub(load3(ps_position, v), shown), common)))
    if common >= 1.0:
        passes = 0   # every particle reached its target
    else:
        passes = DISPLAY_MOVE_PASSES
    for _ in range(passes):
        for v in range(start, end):
            if (m_attribute[v] & MOVE) == 0:
                continue
            shown = load3(ps_disp_pos, v)
            move = v_sub(load3(ps_position, v), shown)
            if v_dot(move, move) == 0.0:
                continue
            fraction = 1.0
            for link in range(m_distance_start[v], m_distance_start[v] + m_distance_count[v]):
                u = m_distance_target[link]
                fraction = min(fraction, safe_fraction(v_sub(shown, load3(ps_disp_pos, u)), move,
                                                       display_edge_bound(ps, v, u, dt)))
            store3(ps_disp_pos, v, v_add(shown, v_scale(move, fraction)))
    for p in range(start, end):
        store3(ps_position, p, load3(ps_disp_pos, p))
