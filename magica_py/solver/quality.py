"""Quality mode passes at the end of a step (``docs/quality-mode.md``).

MagicaCloth2's constraints are soft (docs/solver.md Appendix 4): edges stretch by 5-60 % under load and
fast particles end a step inside colliders. Quality mode adds, after the second distance pass
and the motion constraint (D.9), before the end of the step (D.10):

1. an inextensibility pass chosen by the ``inextensibility`` parameter (``P[b, PRM_INEXTENSIBILITY]``):

   * ``tether`` — a tight long-range attachment (Kim et al. 2012): each moving particle's
     distance to its root is clamped to its step-basic rest distance x (1 + tether_limit);
   * ``ftl`` — follow-the-leader (Mueller et al. 2012): along every baseline, root to tip,
     each edge longer than its step-basic rest length is shortened by moving the child
     only; the DFTL velocity correction gives the parent ``-s_damp x`` the child's
     correction as velocity (its reaction), so the pass does not damp the swing;
   * ``ftl_tether`` — the tether, then FTL (edges exact, root distance bounded);
   * ``iterations`` — ``distance_iterations`` more D.4 passes (the brute-force candidate);
   * ``ftl_edges`` — on a mesh cloth (proxy edges besides the parent links: a skirt's
     horizontal links and triangle diagonals) first the edge projection
     (``edge_projection_lane``: every stretched edge at once, a linearised solve by
     conjugate gradients), then ``distance_iterations`` Gauss-Seidel passes of a unilateral
     PBD projection over every proxy edge (depth-weighted masses as D.4, fixed ends
     immovable), both in ``edge_projection.py``, then the tether and FTL;

   With ``restoration_drift`` (quality default) the pass runs without D.6's drift: the angle
   pass's kept-out share, taken out of the positions from the angle pass on (``drift_*``),
   is put back after it and projected by the same passes without velocity
   (docs/quality-mode.md, *Convergence*);

2. ``collision_last``: a final point projection of every colliding particle against each
   collider in turn (two rounds), so that no particle ends the step inside one; a particle
   that started the step inside a collider is carried out with it without the starting depth
   becoming velocity (``collision_last_push``). A colliding line cloth under an FTL mode then
   runs follow-the-leader again with the colliders (``ftl_collision_lane``): a pushed particle
   keeps its place and its edges pull the rest of the chain. A colliding mesh cloth under ``ftl_edges``
   then runs ``SHAPE_ROUNDS - 1`` more rounds of (edge projection in which the particles
   collision last pushed slide along their push's plane, edge passes, collision last), so
   that the push's stretch is spread over the mesh instead of left on the pushed edges.

The quality display (``display.py``) ends with ``quality_display.display_constraints_block``:
collider push at this frame's pose within edge bounds taken from the step states.

Every pass is unilateral (only stretch is removed) and uses the step-basic pose (D.2) as the
rest reference, like the tether of D.3. Faithful mode never calls this module.

Lane form (``solver/lanes.py``): the passes whose work follows the topology (the tight tether,
FTL, the edge passes, the drift's put-back, D.4's passes) run every lane of a block side by
side (``*_block``, ``edge_projection.edge_pass_lanes``), a partner particle's rows gathered next to the particle
being solved; the conjugate-gradient projection, collision last and FTL with the colliders,
whose work depends on each lane's state (active edges, early exits, pushes), run lane by lane
(``*_lane``).
"""
from __future__ import annotations

from magica_py.build.proxy import DISABLE_COLLISION, MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    q_rotate, v_add, v_dot, v_length, v_length_sq, v_lerp, v_normalize, v_scale, v_sub,
)
from magica_py.solver.constraints.collision import (
    PLANE, SPHERE, particle_radius, plane_push, segment_parameter, solve_point_collider,
)
from magica_py.solver.constraints.distance import distance_block
from magica_py.solver.constraints.tether import gather_partner_step_pose
from magica_py.solver.edge_projection import (
    PROJECTION_ITERATIONS, edge_pass_lanes, edge_projection_lane, has_cross_links, stretched_lanes,
)
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import get1, get3, get4, put3
from magica_py.solver.parameters import (
    PRM_COLLISION_LAST, PRM_COLLISION_MODE, PRM_DISTANCE_FULL_VELOCITY, PRM_DISTANCE_ITERATIONS, PRM_FTL_DAMPING,
    PRM_INEXTENSIBILITY, PRM_QUALITY, PRM_RESTORATION_ATTENUATION, PRM_RESTORATION_DRIFT, PRM_TETHER_LIMIT,
)
from magica_py.kernels import portable

INEXT_NONE = 0
INEXT_TETHER = 1
INEXT_FTL = 2
INEXT_FTL_TETHER = 3
INEXT_ITERATIONS = 4
INEXT_FTL_EDGES = 5
INSIDE_TOLERANCE = 1e-6   # m
COLLISION_LAST_ROUNDS = 2  # rounds over the colliders of collision last
FTL_COLLISION_ITERATIONS = 4  # alternations of (parent ball, collider push) of the line cloth's FTL after collision last
SHAPE_ROUNDS = 2           # rounds of (edge projection, passes, collision last) of a colliding mesh cloth
ZERO3 = (0.0, 0.0, 0.0)


@kernel
def clamp_to_sphere(x, center, radius):
    """``x`` moved onto the sphere (center, radius) when it lies outside it; and the move."""
    v = v_sub(x, center)
    length = v_length(v)
    if length <= radius or length < 1e-12:
        return x, (0.0, 0.0, 0.0)
    target = v_add(center, v_scale(v, radius / length))
    return target, v_sub(target, x)


@kernel(forceinline=False)
def tight_tether_block(PS, P, BI, topology, b):
    """Root distance of every moving particle <= step-basic rest x (1 + tether_limit), every
    lane of block b side by side (the root's rows gathered next to the particle's first).
    The correction becomes velocity in full (plain PBD)."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute, root_index = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_ROOT_INDEX]
    limit = 1.0 + P[b, PRM_TETHER_LIMIT]
    for j in range(BI[b, bk.BI_N]):
        if (topology[attribute + j] & MOVE) == 0:
            continue
        r = topology[root_index + j]
        if r < 0:
            continue
        g = g0 + j
        gr = g0 + r
        gather_partner_step_pose(PS, g, gr, w)   # the root's values next to the particle's
        for l in range(w):
            rest = v_length(v_sub(get3(PS, g, st.STEP_BASIC_POS, l), get3(PS, g, st.PARTNER_BASE, l)))
            x, _move = clamp_to_sphere(get3(PS, g, st.NEXT_POS, l), get3(PS, g, st.PARTNER_POS, l), rest * limit)
            put3(PS, g, st.NEXT_POS, l, x)


@kernel(forceinline=False)
def ftl_pass_block(PS, BI, topology, b, damping):
    """Follow-the-leader along each baseline (parents before children), every lane of block b
    side by side: every edge is at most its step-basic rest length. DFTL: the parent's
    velocity gets ``-damping`` x the child's correction (velocity_pos += damping x correction;
    the block's ``ftl_damping``, 0 for the drift's second pass). The parent's rows are gathered
    next to the child's, the child's move kept in ``ACCUM3`` for the parent's share."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute, parent = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_PARENT]
    bl_start, bl_count, bl_data = BI[b, bk.BI_BASELINE_START], BI[b, bk.BI_BASELINE_COUNT], BI[b, bk.BI_BASELINE_DATA]
    for line in range(BI[b, bk.BI_BASELINES]):
        e0 = topology[bl_start + line]
        for e in range(e0 + 1, e0 + topology[bl_count + line]):
            v = topology[bl_data + e]
            if (topology[attribute + v] & MOVE) == 0:
                continue
            p = topology[parent + v]
            if p < 0:
                continue
            gv = g0 + v
            gp = g0 + p
            gather_partner_step_pose(PS, gv, gp, w)   # the parent's values next to the child's
            for l in range(w):
                rest = v_length(v_sub(get3(PS, gv, st.STEP_BASIC_POS, l), get3(PS, gv, st.PARTNER_BASE, l)))
                x, move = clamp_to_sphere(get3(PS, gv, st.NEXT_POS, l), get3(PS, gv, st.PARTNER_POS, l), rest)
                put3(PS, gv, st.NEXT_POS, l, x)
                put3(PS, gv, st.ACCUM3, l, move)
            if damping > 0.0 and (topology[attribute + p] & MOVE) != 0:
                for l in range(w):
                    put3(PS, gp, st.VELOCITY_POS, l, v_add(get3(PS, gp, st.VELOCITY_POS, l),
                                                           v_scale(get3(PS, gv, st.ACCUM3, l), damping)))


@kernel(forceinline=False)
def ftl_collision_lane(PS, PP, TS, CS, P, BI, topology, b, l):
    """Follow-the-leader with the colliders, after collision last, for a line cloth (lane l of
    block b): along each baseline, parents first, a child is moved into the ball of its
    step-basic rest length around its (final) parent and out of the team's colliders at this
    step's pose (``step_collider_push``), alternately, ``FTL_COLLISION_ITERATIONS`` times at
    most, the collider push last: alternating projections towards a point of both sets (for a
    parent outside a convex collider, or inside it by less than the rest length like a root
    fixed inside one, the set is not empty). A pushed particle keeps its place and its edges
    pull the free end, the rest of the chain towards the tip, instead of being left stretched.
    The start-of-step carry was collision last's (it already ran); the moves become velocity,
    with the parent's DFTL correction as in ``ftl_pass_block`` for the ball's share."""
    g0 = BI[b, bk.BI_G0]
    attribute, parent = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_PARENT]
    bl_start, bl_count, bl_data = BI[b, bk.BI_BASELINE_START], BI[b, bk.BI_BASELINE_COUNT], BI[b, bk.BI_BASELINE_DATA]
    c0 = BI[b, bk.BI_COLLIDER0]
    colliders = BI[b, bk.BI_COLLIDERS]
    shapes = BI[b, bk.BI_COLLIDER_SHAPE]
    damping = P[b, PRM_FTL_DAMPING]
    scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)
    for line in range(BI[b, bk.BI_BASELINES]):
        e0 = topology[bl_start + line]
        for e in range(e0 + 1, e0 + topology[bl_count + line]):
            v = topology[bl_data + e]
            attr = topology[attribute + v]
            if (attr & MOVE) == 0:
                continue
            p = topology[parent + v]
            if p < 0:
                continue
            gv = g0 + v
            gp = g0 + p
            hits = (attr & DISABLE_COLLISION) == 0
            r = particle_radius(get1(PP, gv, bk.CURVE_RADIUS, l), scale)
            rest = v_length(v_sub(get3(PS, gv, st.STEP_BASIC_POS, l), get3(PS, gp, st.STEP_BASIC_POS, l)))
            parent_pos = get3(PS, gp, st.NEXT_POS, l)
            if hits:
                # no point of the ball is outside a collider the parent is deeper in than the
                # rest length (a fixed root passing through it): collision wins
                feasible = True
                for c in range(colliders):
                    k = c0 + c
                    if get1(CS, k, st.SCALE_SUSPEND, l) == 0.0 and v_length(
                            v_sub(step_collider_push(CS, k, l, topology[shapes + c], parent_pos, r),
                                  parent_pos)) >= rest:
                        feasible = False
                if not feasible:
                    continue
            x = get3(PS, gv, st.NEXT_POS, l)
            pulled = ZERO3
            for _ in range(FTL_COLLISION_ITERATIONS):
                x, move = clamp_to_sphere(x, parent_pos, rest)
                pulled = v_add(pulled, move)
                if not hits or (move[0] == 0.0 and move[1] == 0.0 and move[2] == 0.0):
                    break
                x0 = x
                for c in range(colliders):
                    k = c0 + c
                    if get1(CS, k, st.SCALE_SUSPEND, l) == 0.0:
                        x = step_collider_push(CS, k, l, topology[shapes + c], x, r)
                if x[0] == x0[0] and x[1] == x0[1] and x[2] == x0[2]:
                    break
            put3(PS, gv, st.NEXT_POS, l, x)
            if damping > 0.0 and (topology[attribute + p] & MOVE) != 0:
                put3(PS, gp, st.VELOCITY_POS, l, v_add(get3(PS, gp, st.VELOCITY_POS, l), v_scale(pulled, damping)))


@kernel(forceinline=False)
def collision_last_lane(PS, PP, TS, CS, BI, topology, b, l, carry):
    """Project every colliding moving particle of lane l of block b out of each collider
    (``collision_last_push``), ``COLLISION_LAST_ROUNDS`` rounds over the colliders so that a
    push out of one collider into another is undone. Friction and normals are left to D.8.
    ``carry``: a particle that started the step inside is carried out without its starting
    depth becoming velocity (the first call of a step; a later call only undoes the
    inextensibility passes in between, whose corrections became velocity, so its push does
    too). The direction of each push is kept in ``PROJECTION_CONTACT`` for the next edge
    projection. Returns the number of particles it moved."""
    g0 = BI[b, bk.BI_G0]
    attribute = BI[b, bk.BI_ATTRIBUTE]
    c0 = BI[b, bk.BI_COLLIDER0]
    colliders = BI[b, bk.BI_COLLIDERS]
    shapes = BI[b, bk.BI_COLLIDER_SHAPE]
    scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)
    pushed = 0
    for j in range(BI[b, bk.BI_N]):
        attr = topology[attribute + j]
        if (attr & MOVE) == 0 or (attr & DISABLE_COLLISION) != 0:
            continue
        g = g0 + j
        r = particle_radius(get1(PP, g, bk.CURVE_RADIUS, l), scale)
        x = get3(PS, g, st.NEXT_POS, l)
        start_x = get3(PS, g, st.OLD_POS, l)
        velocity_pos = get3(PS, g, st.VELOCITY_POS, l)
        x0 = x
        for _ in range(COLLISION_LAST_ROUNDS):
            for c in range(colliders):
                k = c0 + c
                if get1(CS, k, st.SCALE_SUSPEND, l) == 0.0:
                    x, velocity_pos = collision_last_push(CS, k, l, topology[shapes + c], x, start_x, velocity_pos, r,
                                                          INSIDE_TOLERANCE * scale, carry)
        push = v_sub(x, x0)
        if v_dot(push, push) > 0.0:
            put3(PS, g, st.PROJECTION_CONTACT, l, v_normalize(push))
            pushed += 1
        put3(PS, g, st.NEXT_POS, l, x)
        put3(PS, g, st.VELOCITY_POS, l, velocity_pos)
    return pushed


@kernel
def collision_last_push(CS, k, l, shape, x, start_x, velocity_pos, r, tolerance, carry):
    """One particle (end-of-step position x, radius r, start-of-step position ``start_x``)
    against collider slot k of lane l (of shape ``shape``) moving from its previous-step to its
    current pose within the step: (x, velocity_pos) after the push. ``tolerance`` (m): the
    depth below which it counts as having started outside (a particle projected by the last
    step lies on the surface).

    A particle that started the step outside is pushed by D.8's moving plane (normal from the
    previous pose, surface at the current one): it ends on the supporting plane of the surface
    point, so outside the collider, and the push becomes velocity (the collider's motion).

    A particle that started the step inside (a collider that appeared, grew or was squeezed
    into it) is carried with the collider: its side is the direction from the axis to
    ``start_x`` at the previous pose, turned with the collider to the current pose (not the
    nearest surface of ``x``, which flips to the far side once a thick collider has moved past
    its axis), and it is pushed onto the supporting plane there. The share of the push that
    removes the depth it started with does not become velocity (``velocity_pos`` moves with
    it): it leaves with the collider's motion along that side and its own, not thrown out by
    the depth it was found at."""
    depth = start_depth(CS, k, l, shape, start_x, r)
    if depth <= tolerance or shape == PLANE:
        bmin = (x[0] - 2.0 * r, x[1] - 2.0 * r, x[2] - 2.0 * r)
        bmax = (x[0] + 2.0 * r, x[1] + 2.0 * r, x[2] + 2.0 * r)
        d, n, x2 = solve_point_collider(CS, k, l, shape, x, r, bmin, bmax)
        if d >= 0.0:
            return x, velocity_pos
    else:
        radius_start = get1(CS, k, st.RADIUS_START, l)
        if shape == SPHERE:
            t = 0.0
            n = v_normalize(v_sub(start_x, get3(CS, k, st.START_OLD, l)))
            surface = v_add(get3(CS, k, st.START_NEW, l), v_scale(n, radius_start + r))
        else:
            so = get3(CS, k, st.START_OLD, l)
            eo = get3(CS, k, st.END_OLD, l)
            t = segment_parameter(start_x, so, eo)
            u = q_rotate(get4(CS, k, st.INVERSE_OLD_ROT, l), v_sub(start_x, v_lerp(so, eo, t)))
            n = v_normalize(q_rotate(get4(CS, k, st.NOW_ROT, l), u))
            radius = radius_start + (get1(CS, k, st.RADIUS_END, l) - radius_start) * t
            surface = v_add(v_lerp(get3(CS, k, st.START_NEW, l), get3(CS, k, st.END_NEW, l), t),
                            v_scale(n, radius + r))
        if v_length_sq(n) < 0.5:   # started on the axis: no side, the nearest surface
            bmin = (x[0] - 2.0 * r, x[1] - 2.0 * r, x[2] - 2.0 * r)
            bmax = (x[0] + 2.0 * r, x[1] + 2.0 * r, x[2] + 2.0 * r)
            d, n, x2 = solve_point_collider(CS, k, l, shape, x, r, bmin, bmax)
        else:
            d, x2 = plane_push(surface, n, x)
        if d >= 0.0:
            return x, velocity_pos
        if carry:
            along = v_dot(v_sub(x2, x), n)
            velocity_pos = v_add(velocity_pos, v_scale(n, min(depth, along)))
    return x2, velocity_pos


@kernel
def push_out_of_ball(x, c, reach):
    """``x`` moved radially onto the sphere of radius ``reach`` around ``c`` when it lies inside
    it; unchanged outside or at the centre (no direction). The last move of the collider
    pushes of collision last's follow-the-leader and of the quality display."""
    v = v_sub(x, c)
    length = v_length(v)
    if length >= reach or length < 1e-12:
        return x
    return v_add(c, v_scale(v, reach / length))


@kernel
def step_collider_push(CS, k, l, shape, x, r):
    """``x`` (a sphere of radius r) moved onto the surface of collider slot k of lane l (of shape
    ``shape``) at its pose of this step (``START_NEW`` / ``END_NEW``, ``PLANE_NORMAL``) when it
    lies inside it, along the shortest way out (the nearest point of a sphere or capsule
    surface, or the plane's normal); unchanged otherwise or on the capsule's axis. Unlike D.8's
    moving plane (normal from the previous pose) the set it projects onto does not depend on
    the collider's motion: the alternation of ``ftl_collision_lane`` projects onto two fixed
    sets."""
    if shape == PLANE:
        n = get3(CS, k, st.PLANE_NORMAL, l)
        d = v_dot(v_sub(x, get3(CS, k, st.START_NEW, l)), n) - r
        return v_sub(x, v_scale(n, d)) if d < 0.0 else x
    c, radius = step_axis_point(CS, k, l, shape, x)
    return push_out_of_ball(x, c, radius + r)


@kernel
def step_axis_point(CS, k, l, shape, x):
    """The point of sphere or capsule slot k of lane l at its pose of this step (``START_NEW``
    / ``END_NEW``) nearest to x on its centre or axis, and the collider's radius there:
    (point, radius). The surface nearest to x lies ``radius`` from the point."""
    a = get3(CS, k, st.START_NEW, l)
    if shape == SPHERE:
        t = 0.0
        c = a
    else:
        e = get3(CS, k, st.END_NEW, l)
        t = segment_parameter(x, a, e)
        c = v_lerp(a, e, t)
    radius_start = get1(CS, k, st.RADIUS_START, l)
    return c, radius_start + (get1(CS, k, st.RADIUS_END, l) - radius_start) * t


@kernel
def start_depth(CS, k, l, shape, x, r):
    """How deep the particle sphere (x, r) lay inside collider slot k of lane l (of shape
    ``shape``) at its previous-step pose (m; <= 0 outside)."""
    so = get3(CS, k, st.START_OLD, l)
    radius_start = get1(CS, k, st.RADIUS_START, l)
    if shape == PLANE:
        return r - v_dot(v_sub(x, so), get3(CS, k, st.PLANE_NORMAL, l))
    if shape == SPHERE:
        return radius_start + r - v_length(v_sub(x, so))
    eo = get3(CS, k, st.END_OLD, l)
    t = segment_parameter(x, so, eo)
    radius = radius_start + (get1(CS, k, st.RADIUS_END, l) - radius_start) * t
    return radius + r - v_length(v_sub(x, v_lerp(so, eo, t)))


@kernel(inline="always")
def quality_distance_attenuation(P, b, faithful_attenuation):
    """D.4's velocity attenuation: 0 (full PBD velocity) when distance_full_velocity is on."""
    if P[b, PRM_DISTANCE_FULL_VELOCITY] != 0.0:
        return 0.0
    return faithful_attenuation


@kernel
def quality_hard_attenuation(P, b, frequency_ratio, attenuation, converted):
    """Velocity attenuation of a hard limit (tether D.3, angle limit D.5, motion D.9) at the
    step size. When a limit removes a step's penetration, ``1 - attn`` of the normal velocity
    survives into the next step: a per-step retention, so quality mode converts it as one,
    ``attn^(90/f)``, as the frequency-consistent mode does too (``converted``; converting attn
    as a rate let the surviving share tend to 1 - and the limit to a hard bounce - as f grows)."""
    if P[b, PRM_QUALITY] == 0.0:
        return converted
    return portable.pow(attenuation, frequency_ratio)


@kernel(inline="always")
def quality_restoration_attenuation(P, b, frequency_ratio, converted):
    """D.6's velocity attenuation at the step size. Quality mode scales the share of the
    restoration correction that becomes velocity, ``1 - attn``, linearly with the step
    (``(1 - attn) 90/f``): the correction itself is about proportional to the step, so the
    velocity it leaves per unit time stays the same at any frequency, as the
    frequency-consistent mode does too (``converted``; converted as a rate, that share tends to
    1 as f grows, and the restoration then acts as a force growing with f: 29 % of the tail's
    length between 90 and 1440 Hz)."""
    if P[b, PRM_QUALITY] == 0.0:
        return converted
    share = (1.0 - P[b, PRM_RESTORATION_ATTENUATION]) * frequency_ratio
    return 1.0 - (1.0 if share > 1.0 else (0.0 if share < 0.0 else share))


@kernel
def inextensibility_passes(PS, PM, PP, TS, TM, LM, EDS, P, BI, topology, b, frequency_ratio, power_y,
                           distance_attenuation, mode, mesh, damping):
    """The inextensibility pass ``mode`` (module docstring) over every lane of block b;
    ``mesh``: the block has cross links (``has_cross_links``) and ``ftl_edges`` starts with
    the edge projection (lane by lane); ``damping``: FTL's DFTL factor."""
    w = bk.lane_width(BI, b)
    iterations = int(P[b, PRM_DISTANCE_ITERATIONS])
    if mode == INEXT_FTL_EDGES:
        if mesh:
            stretched_lanes(PS, TS, BI, topology, b, w)
            for l in range(w):
                if get1(TS, b, st.PROJECTION_NEEDED, l) != 0.0:
                    edge_projection_lane(PS, PM, EDS, BI, topology, b, l, PROJECTION_ITERATIONS, False)
        for _ in range(iterations):
            edge_pass_lanes(PS, PM, BI, topology, b, 0, w)
    if mode == INEXT_TETHER or mode == INEXT_FTL_TETHER or mode == INEXT_FTL_EDGES:
        tight_tether_block(PS, P, BI, topology, b)
    if mode == INEXT_FTL or mode == INEXT_FTL_TETHER or mode == INEXT_FTL_EDGES:
        ftl_pass_block(PS, BI, topology, b, damping)
    elif mode == INEXT_ITERATIONS:
        for _ in range(iterations):
            distance_block(PS, PM, PP, TS, TM, LM, P, BI, topology, b, frequency_ratio, power_y, distance_attenuation)


@kernel(forceinline=False)
def collision_last_rounds_lane(PS, PM, PP, TS, CS, EDS, P, BI, topology, b, l, mode, mesh):
    """Collision last of lane l of block b and what follows it (``quality_end_of_step_block``):
    the follow-the-leader with the colliders of a line cloth under an FTL mode, or the further
    rounds of a mesh cloth under ``ftl_edges``."""
    if mesh:
        g0 = BI[b, bk.BI_G0]
        for j in range(BI[b, bk.BI_N]):
            put3(PS, g0 + j, st.PROJECTION_CONTACT, l, ZERO3)
    pushed = collision_last_lane(PS, PP, TS, CS, BI, topology, b, l, True)
    if not mesh and pushed > 0 and (mode == INEXT_FTL or mode == INEXT_FTL_TETHER or mode == INEXT_FTL_EDGES):
        ftl_collision_lane(PS, PP, TS, CS, P, BI, topology, b, l)
    if mesh:
        iterations = int(P[b, PRM_DISTANCE_ITERATIONS])
        for _ in range(SHAPE_ROUNDS - 1):
            if pushed == 0 or not edge_projection_lane(PS, PM, EDS, BI, topology, b, l, PROJECTION_ITERATIONS, True):
                break
            for _ in range(iterations):
                edge_pass_lanes(PS, PM, BI, topology, b, l, l + 1)
            pushed = collision_last_lane(PS, PP, TS, CS, BI, topology, b, l, False)


@kernel(forceinline=False)
def quality_end_of_step_block(PS, PM, PP, TS, TM, CS, LM, EDS, P, BI, topology, b, frequency_ratio, power_y,
                              distance_attenuation, drift):
    """The quality passes of block b after D.9 (see the module docstring): the
    inextensibility pass, then collision last. A mesh cloth under ``ftl_edges`` that collides
    then runs ``SHAPE_ROUNDS - 1`` more rounds of (edge projection with the particles that
    collision last pushed sliding along their push's plane, edge passes, collision last),
    while collision last moves a particle and the push leaves an edge stretched by more than
    ``PROJECTION_THRESHOLD``: collision last
    pushes particles out along the collider's normal, which stretches the edges the passes had
    just shortened; the filtered projection shortens them again by moving the pushed
    particles' neighbours and the pushed particles along the collider, not back into it.
    Every round ends with collision last, so no particle ends the step inside a collider.
    The passes over the topology run every lane side by side; collision last and what follows
    it run lane by lane (``collision_last_rounds_lane``: each lane's pushes decide its work).

    ``drift``: ``QUALITY_DRIFT`` holds this step's restoration drift, taken out of the
    positions since the angle pass (``drift_begin_block`` / ``drift_end_block`` around it): put
    back after the inextensibility pass (``drift_in_block``)."""
    mode = int(P[b, PRM_INEXTENSIBILITY])
    mesh = mode == INEXT_FTL_EDGES and has_cross_links(BI, topology, b)
    collide = P[b, PRM_COLLISION_LAST] != 0.0 and BI[b, bk.BI_COLLIDERS] > 0 and P[b, PRM_COLLISION_MODE] != 0.0
    inextensibility_passes(PS, PM, PP, TS, TM, LM, EDS, P, BI, topology, b, frequency_ratio, power_y,
                           distance_attenuation, mode, mesh, P[b, PRM_FTL_DAMPING])
    if drift:
        drift_in_block(PS, PM, PP, TS, TM, LM, EDS, P, BI, topology, b, frequency_ratio, power_y, distance_attenuation,
                       mode, mesh)
    if not collide:
        return
    for l in range(bk.lane_width(BI, b)):
        collision_last_rounds_lane(PS, PM, PP, TS, CS, EDS, P, BI, topology, b, l, mode, mesh)


@kernel
def drift_applies(P, b):
    """Does block b take its restoration drift out of the passes (``restoration_drift`` on an
    inextensibility pass that projects: tether, FTL, ``ftl_edges``)?"""
    mode = int(P[b, PRM_INEXTENSIBILITY])
    return P[b, PRM_RESTORATION_DRIFT] != 0.0 and mode != INEXT_NONE and mode != INEXT_ITERATIONS


@kernel(forceinline=False)
def drift_begin_block(PS, BI, b):
    """Before the angle pass (D.5/D.6) of a quality block with ``restoration_drift``: keep
    velocity_pos in ``QUALITY_DRIFT``."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    for g in range(g0, g0 + BI[b, bk.BI_N]):
        for l in range(w):
            put3(PS, g, st.QUALITY_DRIFT, l, get3(PS, g, st.VELOCITY_POS, l))


@kernel(forceinline=False)
def drift_end_block(PS, BI, topology, b):
    """After the angle pass: ``QUALITY_DRIFT`` = what the pass moved velocity_pos by, i.e. the
    share of its correction it kept out of the velocity (quality mode: ``1 - (1 - attn) 90/f``
    of the restoration's, the drift; and the angle limit's retention). The drift is then taken
    out of next_pos and velocity_pos of the moving particles (the velocity, their difference,
    does not change) until the inextensibility pass has run: the constraints after the angle
    pass (bending, collision, D.4's second pass, motion) and the inextensibility passes see the
    step's motion without it, so they turn into velocity only the stretch that motion made."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        move = (topology[attribute + j] & MOVE) != 0
        for l in range(w):
            vp = get3(PS, g, st.VELOCITY_POS, l)
            o = v_sub(vp, get3(PS, g, st.QUALITY_DRIFT, l))
            put3(PS, g, st.QUALITY_DRIFT, l, o)
            if move:
                put3(PS, g, st.NEXT_POS, l, v_sub(get3(PS, g, st.NEXT_POS, l), o))
                put3(PS, g, st.VELOCITY_POS, l, v_sub(vp, o))


@kernel(forceinline=False)
def drift_in_block(PS, PM, PP, TS, TM, LM, EDS, P, BI, topology, b, frequency_ratio, power_y, distance_attenuation,
                   mode, mesh):
    """The drift put back into next_pos and velocity_pos after the inextensibility pass, then
    the pass again (no DFTL reaction; a line cloth's tether and FTL only, a mesh cloth's without
    the edge projection) over the drifted positions with velocity_pos moved with every
    correction: the constraints bend the drift (its share along a taut edge is
    removed) and none of it becomes velocity. Without this, the passes removed the drift's
    stretch as velocity at every step, a share per step that per second grew with f
    (docs/quality-mode.md, *Convergence*). Every lane of block b side by side; the drifted
    position is kept in ``QUALITY_DRIFT`` during the pass."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    n = BI[b, bk.BI_N]
    attribute = BI[b, bk.BI_ATTRIBUTE]
    for j in range(n):
        if (topology[attribute + j] & MOVE) == 0:
            continue
        g = g0 + j
        for l in range(w):
            o = get3(PS, g, st.QUALITY_DRIFT, l)
            x = v_add(get3(PS, g, st.NEXT_POS, l), o)
            put3(PS, g, st.NEXT_POS, l, x)
            put3(PS, g, st.VELOCITY_POS, l, v_add(get3(PS, g, st.VELOCITY_POS, l), o))
            put3(PS, g, st.QUALITY_DRIFT, l, x)
    # a line cloth's edges are its parent links, which follow-the-leader alone brings within
    # their rest lengths: its edge passes are left out here (the tether and FTL remain)
    drift_mode = INEXT_FTL_TETHER if (mode == INEXT_FTL_EDGES and not mesh) else mode
    inextensibility_passes(PS, PM, PP, TS, TM, LM, EDS, P, BI, topology, b, frequency_ratio, power_y,
                           distance_attenuation, drift_mode, False, 0.0)
    for j in range(n):
        if (topology[attribute + j] & MOVE) == 0:
            continue
        g = g0 + j
        for l in range(w):
            moved = v_sub(get3(PS, g, st.NEXT_POS, l), get3(PS, g, st.QUALITY_DRIFT, l))
            put3(PS, g, st.VELOCITY_POS, l, v_add(get3(PS, g, st.VELOCITY_POS, l), moved))
            put3(PS, g, st.QUALITY_DRIFT, l, ZERO3)
