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
   * ``ftl_edges`` — on a mesh cloth (proxy edges besides the parent links: a skirt's
     horizontal links and triangle diagonals) first the edge projection
     (``edge_projection_team``: every stretched edge at once, a linearised solve by
     conjugate gradients), then ``distance_iterations`` Gauss-Seidel passes of a unilateral
     PBD projection over every proxy edge (depth-weighted masses as D.4, fixed ends
     immovable), then the tether and FTL;

   With ``restoration_drift`` (quality default) the pass runs without D.6's drift: the angle
   pass's kept-out share, taken out of the positions from the angle pass on (``drift_*``),
   is put back after it and projected by the same passes without velocity
   (docs/quality-mode.md, *Convergence*);

2. ``collision_last``: a final point projection of every colliding particle against each
   collider in turn (two rounds), so that no particle ends the step inside one; a particle
   that started the step inside a collider is carried out with it without the starting depth
   becoming velocity (``collision_last_push``). A colliding line cloth under an FTL mode then
   runs follow-the-leader again with the colliders (``ftl_collision_team``): a pushed particle
   keeps its place and its edges pull the rest of the chain. A colliding mesh cloth under ``ftl_edges``
   then runs ``SHAPE_ROUNDS - 1`` more rounds of (edge projection in which the particles
   collision last pushed slide along their push's plane, edge passes, collision last), so
   that the push's stretch is spread over the mesh instead of left on the pushed edges.

The quality display (``display.py``) ends with ``quality_display.display_constraints_team``:
collider push at this frame's pose within edge bounds taken from the step states.

Every pass is unilateral (only stretch is removed) and uses the step-basic pose (D.2) as the
rest reference, like the tether of D.3. Faithful mode never calls this module.
"""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    inverse_mass_friction_depth, load3, load4, q_rotate, store3, v_add, v_dot, v_length, v_length_sq, v_lerp,
    v_normalize, v_scale, v_sub,
)
from reference_solver.solver.constraints.collision import (
    INVALID_OR_NO_COLLISION, PLANE, SPHERE, particle_radius, plane_push, segment_parameter, solve_point_collider,
)
from reference_solver.solver.constraints.distance import distance_team
from reference_solver.solver.parameters import length_unit
from magica_py.kernels import portable

MOVE = 0x02
INEXT_NONE = 0
INEXT_TETHER = 1
INEXT_FTL = 2
INEXT_FTL_TETHER = 3
INEXT_ITERATIONS = 4
INEXT_FTL_EDGES = 5
INSIDE_TOLERANCE = 1e-6   # m
COLLISION_LAST_ROUNDS = 2  # rounds over the colliders of collision last
PROJECTION_ITERATIONS = 4  # conjugate-gradient iterations of the edge projection (mesh cloths)
PROJECTION_COMPLIANCE = 1e-3  # compliance of an edge at or above its rest length, x (w_a + w_b) (keeps J W J^T definite)
PROJECTION_THRESHOLD = 1.5e-2  # the projection runs when an edge is stretched by more than this share of its rest
PROJECTION_SLACK = 1e-2       # edges down to this share shorter than their rest enter it too, to stay at most as long
PROJECTION_TOLERANCE = 1e-2   # the conjugate gradients stop when the residual's norm fell by this factor
FTL_COLLISION_ITERATIONS = 4  # alternations of (parent ball, collider push) of the line cloth's FTL after collision last
SHAPE_ROUNDS = 2           # rounds of (edge projection, passes, collision last) of a colliding mesh cloth


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
def ftl_pass(m, ps, team, damping):
    """Follow-the-leader along each baseline (parents before children): every edge is at
    most its step-basic rest length. DFTL: the parent's velocity gets ``-damping`` x the
    child's correction (velocity_pos += damping x correction; the team's ``ftl_damping``, 0
    for the drift's second pass)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_baseline_count, m_baseline_data = m.attribute, m.baseline_count, m.baseline_data
    m_baseline_start, m_parent, m_team_baseline_count = m.baseline_start, m.parent, m.team_baseline_count
    ps_next_pos, ps_step_basic_pos, ps_velocity_pos = ps.next_pos, ps.step_basic_pos, ps.velocity_pos
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
def ftl_collision_team(m, ps, prm, ts, cs, team):
    """Follow-the-leader with the colliders, after collision last, for a line cloth: along
    each baseline, parents first, a child is moved into the ball of its step-basic rest length
    around its (final) parent and out of the team's colliders at this step's pose
    (``step_collider_push``), alternately, ``FTL_COLLISION_ITERATIONS`` times at most, the
    collider push last: alternating projections towards a point of both sets (for a parent
    outside a convex collider, or inside it by less than the rest length like a root fixed
    inside one, the set is not empty). A pushed particle keeps its place and its edges pull
    the free end, the rest of the chain towards the tip, instead of being left stretched.
    The start-of-step carry was collision last's (it already ran); the moves become
    velocity, with the parent's DFTL correction as in ``ftl_pass`` for the ball's share."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_baseline_count, m_baseline_data = m.attribute, m.baseline_count, m.baseline_data
    m_baseline_start, m_parent, m_team_baseline_count = m.baseline_start, m.parent, m.team_baseline_count
    ps_next_pos, ps_step_basic_pos, ps_velocity_pos = ps.next_pos, ps.step_basic_pos, ps.velocity_pos
    cs_scale_suspend, m_depth, prm_radius_curve = cs.scale_suspend, m.depth, prm.radius_curve
    damping = prm.ftl_damping[team]
    scale = ts.scale_ratio[team] * length_unit(m, prm, team)
    c0 = ts.collider_start[team]
    c1 = c0 + ts.collider_count[team]
    b0 = m.team_baseline_start[team]
    for b in range(b0, b0 + m_team_baseline_count[team]):
        e0 = m_baseline_start[b]
        for e in range(e0 + 1, e0 + m_baseline_count[b]):
            v = m_baseline_data[e]
            attr = m_attribute[v]
            if (attr & MOVE) == 0:
                continue
            p = m_parent[v]
            if p < 0:
                continue
            hits = (attr & INVALID_OR_NO_COLLISION) == 0
            r = particle_radius(prm_radius_curve, team, m_depth[v], scale)
            rest = v_length(v_sub(load3(ps_step_basic_pos, v), load3(ps_step_basic_pos, p)))
            parent = load3(ps_next_pos, p)
            if hits:
                # no point of the ball is outside a collider the parent is deeper in than the
                # rest length (a fixed root passing through it): collision wins
                feasible = True
                for k in range(c0, c1):
                    if cs_scale_suspend[k] == 0 and \
                            v_length(v_sub(step_collider_push(cs, k, parent, r), parent)) >= rest:
                        feasible = False
                if not feasible:
                    continue
            x = load3(ps_next_pos, v)
            pulled = (0.0, 0.0, 0.0)
            for _ in range(FTL_COLLISION_ITERATIONS):
                x, move = clamp_to_sphere(x, parent, rest)
                pulled = v_add(pulled, move)
                if not hits or (move[0] == 0.0 and move[1] == 0.0 and move[2] == 0.0):
                    break
                x0 = x
                for k in range(c0, c1):
                    if cs_scale_suspend[k] == 0:
                        x = step_collider_push(cs, k, x, r)
                if x[0] == x0[0] and x[1] == x0[1] and x[2] == x0[2]:
                    break
            store3(ps_next_pos, v, x)
            if damping > 0.0 and (m_attribute[p] & MOVE) != 0:
                store3(ps_velocity_pos, p, v_add(load3(ps_velocity_pos, p), v_scale(pulled, damping)))


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
def has_cross_links(m, team):
    """Does the team have a proxy edge that is not a parent link (a mesh cloth's horizontal
    links and triangle diagonals)? Line cloths are held exactly by FTL and skip the projection."""
    m_edges, m_parent = m.edges, m.parent
    e0 = m.team_edge_start[team]
    for e in range(e0, e0 + m.team_edge_count[team]):
        a = m_edges[e, 0]
        b = m_edges[e, 1]
        if m_parent[a] != b and m_parent[b] != a:
            return True
    return False


@kernel
def tangential(v, c):
    """v without its component along the unit (or zero) contact direction c."""
    return v_sub(v, v_scale(c, v_dot(v, c)))


@kernel
def edge_projection_team(m, ps, team, iterations, contacts):
    """Fast projection (Goldenthal et al. 2007) of the team's stretched proxy edges, all at
    once, when one of them is stretched by more than ``PROJECTION_THRESHOLD``: one linearised
    solve of ``(J W S J^T + K) lambda = C`` over the edges at least ``1 - PROJECTION_SLACK``
    times their step-basic rest length (C = max(length - rest, 0): the stretched ones are
    shortened, the others kept from stretching while their neighbours move; J the edges'
    unit directions, W D.4's depth inverse masses with fixed ends 0, K diagonal,
    ``(PROJECTION_COMPLIANCE + s / (1 - s)) (w_a + w_b)`` with s the edge's compression as a
    share of the slack: a shorter edge holds less, and nothing as it leaves the solve, so the
    result is continuous in the positions),
    by ``iterations`` Jacobi-preconditioned conjugate-gradient iterations, then
    ``x -= W S J^T lambda`` with lambda >= 0 (an edge only pulls). The correction becomes
    velocity in full. ``contacts``: S removes, for a particle that collision last pushed
    out of a collider this step, the component along that push (``projection_contact``): it
    slides along the collider's supporting plane and its neighbours give way (a filtered
    solve, Baraff and Witkin 1998); otherwise S = I.

    Gauss-Seidel edge passes shorten an edge by moving its ends along it; the uniform
    expansion of a ring (a flared skirt) needs every particle to move inwards, which each
    pass reaches only through the small angle between neighbouring chords (the slowest mode
    of the ring's edges: 13 % of it per pass on a 12-strand ring). The solve couples every
    edge and removes that mode with the others (conjugate gradients converge in about
    sqrt(condition) iterations, and exactly in as many as the system has distinct
    eigenvalues). Returns whether it ran."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_depth, m_edges = m.attribute, m.depth, m.edges
    ps_friction, ps_next_pos, ps_step_basic_pos = ps.friction, ps.next_pos, ps.step_basic_pos
    ps_w, ps_gather, ps_contact = ps.projection_inverse_mass, ps.projection_gather, ps.projection_contact
    ps_normal, ps_lambda, ps_residual = ps.edge_normal, ps.edge_lambda, ps.edge_residual
    ps_direction, ps_product, ps_diagonal = ps.edge_direction, ps.edge_product, ps.edge_diagonal
    ps_active, ps_compliance = ps.edge_active, ps.edge_compliance
    start = m.team_particle_start[team]
    end = start + m.team_particle_count[team]
    for p in range(start, end):
        ps_w[p] = inverse_mass_friction_depth(ps_friction[p], m_depth[p]) if (m_attribute[p] & MOVE) != 0 else 0.0
    e0 = m.team_edge_start[team]
    count = 0   # the edges in the solve, listed in ps_active[e0:e0 + count]
    stretched = False
    rz = 0.0
    for e in range(e0, e0 + m.team_edge_count[team]):
        a = m_edges[e, 0]
        b = m_edges[e, 1]
        wa = ps_w[a]
        wb = ps_w[b]
        if wa + wb <= 0.0:
            continue
        rest = v_length(v_sub(load3(ps_step_basic_pos, a), load3(ps_step_basic_pos, b)))
        d = v_sub(load3(ps_next_pos, b), load3(ps_next_pos, a))
        length = v_length(d)
        slack = (rest - length) / (rest * PROJECTION_SLACK) if rest > 0.0 else 0.0
        if slack >= 1.0 or length < 1e-12:
            continue
        n = v_scale(d, 1.0 / length)
        c = max(length - rest, 0.0)
        stretched = stretched or length > rest * (1.0 + PROJECTION_THRESHOLD)
        # a shorter edge is kept from stretching less the shorter it is, and not at all at
        # 1 - PROJECTION_SLACK of its rest: its compliance grows from 0 to infinity on the way
        compliance = (PROJECTION_COMPLIANCE + (slack / (1.0 - slack) if slack > 0.0 else 0.0)) * (wa + wb)
        ps_compliance[e] = compliance
        diagonal = compliance
        if contacts:
            diagonal += wa * v_length_sq(tangential(n, load3(ps_contact, a))) \
                + wb * v_length_sq(tangential(n, load3(ps_contact, b)))
        else:
            diagonal += wa + wb
        ps_active[e0 + count] = e
        count += 1
        store3(ps_normal, e, n)
        ps_diagonal[e] = diagonal
        ps_lambda[e] = 0.0
        ps_residual[e] = c
        ps_direction[e] = c / diagonal
        rz += c * c / diagonal
    if not stretched:
        return False
    stop = rz * PROJECTION_TOLERANCE * PROJECTION_TOLERANCE
    beta = 0.0
    for iteration in range(iterations):
        for p in range(start, end):
            store3(ps_gather, p, (0.0, 0.0, 0.0))
        for i in range(e0, e0 + count):   # the search direction (after the first), and W S J^T of it
            e = ps_active[i]
            if iteration > 0:
                ps_direction[e] = ps_residual[e] / ps_diagonal[e] + beta * ps_direction[e]
            de = ps_direction[e]
            a = m_edges[e, 0]
            b = m_edges[e, 1]
            n = load3(ps_normal, e)
            store3(ps_gather, a, v_sub(load3(ps_gather, a), v_scale(n, ps_w[a] * de)))
            store3(ps_gather, b, v_add(load3(ps_gather, b), v_scale(n, ps_w[b] * de)))
        if contacts:
            for p in range(start, end):
                store3(ps_gather, p, tangential(load3(ps_gather, p), load3(ps_contact, p)))
        dad = 0.0
        for i in range(e0, e0 + count):
            e = ps_active[i]
            de = ps_direction[e]
            a = m_edges[e, 0]
            b = m_edges[e, 1]
            ad = v_dot(load3(ps_normal, e), v_sub(load3(ps_gather, b), load3(ps_gather, a))) \
                + ps_compliance[e] * de
            ps_product[e] = ad
            dad += de * ad
        if dad <= 0.0:
            break
        alpha = rz / dad
        rz_next = 0.0
        for i in range(e0, e0 + count):
            e = ps_active[i]
            ps_lambda[e] += alpha * ps_direction[e]
            r = ps_residual[e] - alpha * ps_product[e]
            ps_residual[e] = r
            rz_next += r * r / ps_diagonal[e]
        if rz_next <= stop:
            break
        beta = rz_next / rz
        rz = rz_next
    for i in range(e0, e0 + count):
        e = ps_active[i]
        lam = ps_lambda[e]
        if lam <= 0.0:
            continue
        a = m_edges[e, 0]
        b = m_edges[e, 1]
        n = load3(ps_normal, e)
        da = v_scale(n, ps_w[a] * lam)
        db = v_scale(n, ps_w[b] * lam)
        if contacts:
            da = tangential(da, load3(ps_contact, a))
            db = tangential(db, load3(ps_contact, b))
        store3(ps_next_pos, a, v_add(load3(ps_next_pos, a), da))
        store3(ps_next_pos, b, v_sub(load3(ps_next_pos, b), db))
    return True


@kernel
def collision_last_team(m, ps, prm, ts, cs, team, carry):
    """Project every colliding moving particle out of each collider (``collision_last_push``),
    ``COLLISION_LAST_ROUNDS`` rounds over the colliders so that a push out of one collider
    into another is undone. Friction and normals are left to D.8. ``carry``: a particle that
    started the step inside is carried out without its starting depth becoming velocity
    (the first call of a step; a later call only undoes the inextensibility passes in
    between, whose corrections became velocity, so its push does too). The direction of
    each push is kept in ``projection_contact`` for the next edge projection. Returns the
    number of particles it moved."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    cs_scale_suspend, m_attribute, m_depth = cs.scale_suspend, m.attribute, m.depth
    m_team_particle_count, prm_radius_curve, ps_next_pos = m.team_particle_count, prm.radius_curve, ps.next_pos
    ps_old_pos, ps_velocity_pos, ps_contact = ps.old_pos, ps.velocity_pos, ps.projection_contact
    scale = ts.scale_ratio[team] * length_unit(m, prm, team)
    c0 = ts.collider_start[team]
    c1 = c0 + ts.collider_count[team]
    start = m.team_particle_start[team]
    pushed = 0
    for p in range(start, start + m_team_particle_count[team]):
        attr = m_attribute[p]
        if (attr & MOVE) == 0 or (attr & INVALID_OR_NO_COLLISION) != 0:
            continue
        r = particle_radius(prm_radius_curve, team, m_depth[p], scale)
        x = load3(ps_next_pos, p)
        start_x = load3(ps_old_pos, p)
        velocity_pos = load3(ps_velocity_pos, p)
        x0 = x
        for _ in range(COLLISION_LAST_ROUNDS):
            for k in range(c0, c1):
                if cs_scale_suspend[k] == 0:
                    x, velocity_pos = collision_last_push(cs, k, x, start_x, velocity_pos, r,
                                                          INSIDE_TOLERANCE * scale, carry)
        push = v_sub(x, x0)
        if v_dot(push, push) > 0.0:
            store3(ps_contact, p, v_normalize(push))
            pushed += 1
        store3(ps_next_pos, p, x)
        store3(ps_velocity_pos, p, velocity_pos)
    return pushed


@kernel
def collision_last_push(cs, k, x, start_x, velocity_pos, r, tolerance, carry):
    """One particle (end-of-step position x, radius r, start-of-step position ``start_x``)
    against collider slot k moving from its previous-step to its current pose within the step:
    (x, velocity_pos) after the push. ``tolerance`` (m): the depth below which it counts as
    having started outside (a particle projected by the last step lies on the surface).

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
    shape = cs.shape[k]
    depth = start_depth(cs, k, start_x, r)
    if depth <= tolerance or shape == PLANE:
        bmin = (x[0] - 2.0 * r, x[1] - 2.0 * r, x[2] - 2.0 * r)
        bmax = (x[0] + 2.0 * r, x[1] + 2.0 * r, x[2] + 2.0 * r)
        d, n, x2 = solve_point_collider(cs, k, x, r, bmin, bmax)
        if d >= 0.0:
            return x, velocity_pos
    else:
        if shape == SPHERE:
            t = 0.0
            n = v_normalize(v_sub(start_x, load3(cs.start_old, k)))
            surface = v_add(load3(cs.start_new, k), v_scale(n, cs.radius_start[k] + r))
        else:
            so = load3(cs.start_old, k)
            eo = load3(cs.end_old, k)
            t = segment_parameter(start_x, so, eo)
            u = q_rotate(load4(cs.inverse_old_rot, k), v_sub(start_x, v_lerp(so, eo, t)))
            n = v_normalize(q_rotate(load4(cs.now_rot, k), u))
            radius = cs.radius_start[k] + (cs.radius_end[k] - cs.radius_start[k]) * t
            surface = v_add(v_lerp(load3(cs.start_new, k), load3(cs.end_new, k), t), v_scale(n, radius + r))
        if v_length_sq(n) < 0.5:   # started on the axis: no side, the nearest surface
            bmin = (x[0] - 2.0 * r, x[1] - 2.0 * r, x[2] - 2.0 * r)
            bmax = (x[0] + 2.0 * r, x[1] + 2.0 * r, x[2] + 2.0 * r)
            d, n, x2 = solve_point_collider(cs, k, x, r, bmin, bmax)
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
def step_collider_push(cs, k, x, r):
    """``x`` (a sphere of radius r) moved onto the surface of collider slot k at its pose of
    this step (``start_new`` / ``end_new``, ``plane_normal``) when it lies inside it, along the
    shortest way out (the nearest point of a sphere or capsule surface, or the plane's normal);
    unchanged otherwise or on the capsule's axis. Unlike D.8's moving plane (normal from the
    previous pose) the set it projects onto does not depend on the collider's motion: the
    alternation of ``ftl_collision_team`` projects onto two fixed sets."""
    shape = cs.shape[k]
    a = load3(cs.start_new, k)
    if shape == PLANE:
        n = load3(cs.plane_normal, k)
        d = v_dot(v_sub(x, a), n) - r
        return v_sub(x, v_scale(n, d)) if d < 0.0 else x
    if shape == SPHERE:
        t = 0.0
        c = a
    else:
        b = load3(cs.end_new, k)
        t = segment_parameter(x, a, b)
        c = v_lerp(a, b, t)
    reach = cs.radius_start[k] + (cs.radius_end[k] - cs.radius_start[k]) * t + r
    return push_out_of_ball(x, c, reach)


@kernel
def start_depth(cs, k, x, r):
    """How deep the particle sphere (x, r) lay inside collider slot k at its previous-step
    pose (m; <= 0 outside)."""
    shape = cs.shape[k]
    so = load3(cs.start_old, k)
    if shape == PLANE:
        return r - v_dot(v_sub(x, so), load3(cs.plane_normal, k))
    if shape == SPHERE:
        return cs.radius_start[k] + r - v_length(v_sub(x, so))
    eo = load3(cs.end_old, k)
    t = segment_parameter(x, so, eo)
    radius = cs.radius_start[k] + (cs.radius_end[k] - cs.radius_start[k]) * t
    return radius + r - v_length(v_sub(x, v_lerp(so, eo, t)))


@kernel
def inside_old_pose(cs, k, x, r):
    """Is x (with radius r) deeper than ``INSIDE_TOLERANCE`` inside collider slot k at its
    previous-step pose? (A particle projected by the last step lies on the surface.)"""
    return start_depth(cs, k, x, r) > INSIDE_TOLERANCE


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
    ``attn^(90/f)``, as the frequency-consistent mode does too (``converted``; converting attn
    as a rate let the surviving share tend to 1 - and the limit to a hard bounce - as f grows)."""
    if prm.quality[team] == 0:
        return converted
    return portable.pow(attenuation, frequency_ratio)


@kernel
def quality_restoration_attenuation(prm, team, frequency_ratio, converted):
    """D.6's velocity attenuation at the step size. Quality mode scales the share of the
    restoration correction that becomes velocity, ``1 - attn``, linearly with the step
    (``(1 - attn) 90/f``): the correction itself is about proportional to the step, so the
    velocity it leaves per unit time stays the same at any frequency, as the
    frequency-consistent mode does too (``converted``; converted as a rate, that share tends to
    1 as f grows, and the restoration then acts as a force growing with f: 29 % of the tail's
    length between 90 and 1440 Hz)."""
    if prm.quality[team] == 0:
        return converted
    share = (1.0 - prm.restoration_attenuation[team]) * frequency_ratio
    return 1.0 - (1.0 if share > 1.0 else (0.0 if share < 0.0 else share))


@kernel
def inextensibility_passes(m, ps, prm, ts, team, frequency_ratio, power_y, distance_attenuation, mode, mesh,
                           damping):
    """The inextensibility pass ``mode`` (module docstring); ``mesh``: the team has cross
    links (``has_cross_links``) and ``ftl_edges`` starts with the edge projection; ``damping``:
    FTL's DFTL factor."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    prm_distance_iterations = prm.distance_iterations
    if mode == INEXT_FTL_EDGES:
        if mesh:
            edge_projection_team(m, ps, team, PROJECTION_ITERATIONS, False)
        for _ in range(prm_distance_iterations[team]):
            edge_pass_team(m, ps, team)
    if mode == INEXT_TETHER or mode == INEXT_FTL_TETHER or mode == INEXT_FTL_EDGES:
        tight_tether_team(m, ps, prm, team)
    if mode == INEXT_FTL or mode == INEXT_FTL_TETHER or mode == INEXT_FTL_EDGES:
        ftl_pass(m, ps, team, damping)
    elif mode == INEXT_ITERATIONS:
        for _ in range(prm_distance_iterations[team]):
            distance_team(m, ps, prm, ts, team, frequency_ratio, power_y, distance_attenuation)


@kernel
def quality_end_of_step(m, ps, prm, ts, cs, team, frequency_ratio, power_y, distance_attenuation, drift):
    """The quality passes of one team after D.9 (see the module docstring): the
    inextensibility pass, then collision last. A mesh cloth under ``ftl_edges`` that collides
    then runs ``SHAPE_ROUNDS - 1`` more rounds of (edge projection with the particles that
    collision last pushed sliding along their push's plane, edge passes, collision last),
    while collision last moves a particle and the push leaves an edge stretched by more than
    ``PROJECTION_THRESHOLD``: collision last
    pushes particles out along the collider's normal, which stretches the edges the passes had
    just shortened; the filtered projection shortens them again by moving the pushed
    particles' neighbours and the pushed particles along the collider, not back into it.
    Every round ends with collision last, so no particle ends the step inside a collider.

    ``drift``: ``quality_drift`` holds this step's restoration drift, taken out of the
    positions since the angle pass (``drift_begin_team`` / ``drift_end_team`` around it): put
    back after the inextensibility pass (``drift_in_team``)."""
    mode = prm.inextensibility[team]
    mesh = mode == INEXT_FTL_EDGES and has_cross_links(m, team)
    collide = prm.collision_last[team] != 0 and ts.collider_count[team] > 0 and prm.collision_mode[team] != 0
    inextensibility_passes(m, ps, prm, ts, team, frequency_ratio, power_y, distance_attenuation, mode, mesh,
                           prm.ftl_damping[team])
    if drift:
        drift_in_team(m, ps, prm, ts, team, frequency_ratio, power_y, distance_attenuation, mode, mesh)
    if not collide:
        return
    if mesh:
        ps_contact = ps.projection_contact
        for p in range(m.team_particle_start[team], m.team_particle_start[team] + m.team_particle_count[team]):
            store3(ps_contact, p, (0.0, 0.0, 0.0))
    pushed = collision_last_team(m, ps, prm, ts, cs, team, True)
    if not mesh and pushed > 0 and (mode == INEXT_FTL or mode == INEXT_FTL_TETHER or mode == INEXT_FTL_EDGES):
        ftl_collision_team(m, ps, prm, ts, cs, team)
    if mesh:
        for _ in range(SHAPE_ROUNDS - 1):
            if pushed == 0 or not edge_projection_team(m, ps, team, PROJECTION_ITERATIONS, True):
                break
            for _ in range(prm.distance_iterations[team]):
                edge_pass_team(m, ps, team)
            pushed = collision_last_team(m, ps, prm, ts, cs, team, False)


@kernel
def drift_applies(prm, team):
    """Does the team take its restoration drift out of the passes (``restoration_drift`` on an
    inextensibility pass that projects: tether, FTL, ``ftl_edges``)?"""
    mode = prm.inextensibility[team]
    return prm.restoration_drift[team] != 0 and mode != INEXT_NONE and mode != INEXT_ITERATIONS


@kernel
def drift_begin_team(m, ps, team):
    """Before the angle pass (D.5/D.6) of a quality team with ``restoration_drift``: keep
    velocity_pos in ``quality_drift``."""
    ps_velocity_pos, ps_drift = ps.velocity_pos, ps.quality_drift
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        store3(ps_drift, p, load3(ps_velocity_pos, p))


@kernel
def drift_end_team(m, ps, team):
    """After the angle pass: ``quality_drift`` = what the pass moved velocity_pos by, i.e. the
    share of its correction it kept out of the velocity (quality mode: ``1 - (1 - attn) 90/f``
    of the restoration's, the drift; and the angle limit's retention). The drift is then taken
    out of next_pos and velocity_pos of the moving particles (the velocity, their difference,
    does not change) until the inextensibility pass has run: the constraints after the angle
    pass (bending, collision, D.4's second pass, motion) and the inextensibility passes see the
    step's motion without it, so they turn into velocity only the stretch that motion made."""
    m_attribute, ps_next_pos, ps_velocity_pos, ps_drift = m.attribute, ps.next_pos, ps.velocity_pos, ps.quality_drift
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        vp = load3(ps_velocity_pos, p)
        o = v_sub(vp, load3(ps_drift, p))
        store3(ps_drift, p, o)
        if (m_attribute[p] & MOVE) == 0:
            continue
        store3(ps_next_pos, p, v_sub(load3(ps_next_pos, p), o))
        store3(ps_velocity_pos, p, v_sub(vp, o))


@kernel
def drift_in_team(m, ps, prm, ts, team, frequency_ratio, power_y, distance_attenuation, mode, mesh):
    """The drift put back into next_pos and velocity_pos after the inextensibility pass, then
    the pass again (no DFTL reaction; a line cloth's tether and FTL only, a mesh cloth's without
    the edge projection) over the drifted positions with velocity_pos moved with every
    correction: the constraints bend the drift (its share along a taut edge is
    removed) and none of it becomes velocity. Without this, the passes removed the drift's
    stretch as velocity at every step, a share per step that per second grew with f
    (docs/quality-mode.md, *Convergence*)."""
    m_attribute, ps_next_pos, ps_velocity_pos, ps_drift = m.attribute, ps.next_pos, ps.velocity_pos, ps.quality_drift
    start = m.team_particle_start[team]
    end = start + m.team_particle_count[team]
    for p in range(start, end):
        if (m_attribute[p] & MOVE) == 0:
            continue
        o = load3(ps_drift, p)
        x = v_add(load3(ps_next_pos, p), o)
        store3(ps_next_pos, p, x)
        store3(ps_velocity_pos, p, v_add(load3(ps_velocity_pos, p), o))
        store3(ps_drift, p, x)
    # a line cloth's edges are its parent links, which follow-the-leader alone brings within
    # their rest lengths: its edge passes are left out here (the tether and FTL remain)
    drift_mode = INEXT_FTL_TETHER if (mode == INEXT_FTL_EDGES and not mesh) else mode
    inextensibility_passes(m, ps, prm, ts, team, frequency_ratio, power_y, distance_attenuation, drift_mode, False,
                           0.0)
    for p in range(start, end):
        if (m_attribute[p] & MOVE) == 0:
            continue
        x = load3(ps_next_pos, p)
        store3(ps_velocity_pos, p, v_add(load3(ps_velocity_pos, p), v_sub(x, load3(ps_drift, p))))
        store3(ps_drift, p, (0.0, 0.0, 0.0))
