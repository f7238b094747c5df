"""The edge projection and edge passes of quality mode's ``ftl_edges`` (``docs/quality-mode.md``).

A mesh cloth (proxy edges besides the parent links: a skirt's horizontal links and triangle
diagonals) under ``inextensibility: ftl_edges`` first removes its edges' stretch with these
passes, before the tether and follow-the-leader of ``quality.py``:

* ``edge_projection_lane``: every stretched edge of a lane at once, a linearised solve by
  conjugate gradients (Goldenthal et al. 2007), run for the lanes ``stretched_lanes`` marks;
* ``edge_pass_lanes``: Gauss-Seidel passes of a unilateral PBD projection over every proxy
  edge, every lane of a block side by side, with D.4's depth-weighted inverse masses
  (``projection_masses``; fixed ends immovable).

Every pass is unilateral (only stretch is removed) and measures stretch against the step-basic
pose (D.2). Faithful mode never calls this module.
"""
from __future__ import annotations

from magica_py.build.proxy import MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import inverse_mass_friction_depth, v_add, v_dot, v_length, v_length_sq, v_scale, v_sub
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, put1, put3

PROJECTION_ITERATIONS = 4  # conjugate-gradient iterations of the edge projection (mesh cloths)
PROJECTION_COMPLIANCE = 1e-3  # compliance of an edge at or above its rest length, x (w_a + w_b) (keeps J W J^T definite)
PROJECTION_THRESHOLD = 1.5e-2  # the projection runs when an edge is stretched by more than this share of its rest
PROJECTION_SLACK = 1e-2       # edges down to this share shorter than their rest enter it too, to stay at most as long
PROJECTION_TOLERANCE = 1e-2   # the conjugate gradients stop when the residual's norm fell by this factor
ZERO3 = (0.0, 0.0, 0.0)


@kernel
def projection_masses(PS, PM, BI, topology, b, l0, l1):
    """Every particle's inverse mass of the edge passes and the edge projection, lanes
    ``l0 .. l1 - 1`` of block b, in ``PROJECTION_INVERSE_MASS``: D.4's depth mass
    (``inverse_mass_friction_depth``), 0 when fixed."""
    l1 = min(l1, LANES)   # a lane loop bounded by LANES vectorises (lanes.py)
    g0 = BI[b, bk.BI_G0]
    attribute = BI[b, bk.BI_ATTRIBUTE]
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        if (topology[attribute + j] & MOVE) == 0:
            for l in range(l0, l1):
                put1(PS, g, st.PROJECTION_INVERSE_MASS, l, 0.0)
            continue
        for l in range(l0, l1):
            put1(PS, g, st.PROJECTION_INVERSE_MASS, l,
                 inverse_mass_friction_depth(get1(PS, g, st.FRICTION, l), get1(PM, g, bk.DEPTH, l)))


@kernel(forceinline=False)
def edge_pass_lanes(PS, PM, BI, topology, b, l0, l1):
    """One Gauss-Seidel pass of unilateral edge projection over block b's proxy edges, lanes
    ``l0 .. l1 - 1`` side by side: an edge longer than its step-basic rest length is
    shortened, both ends moving in proportion to their inverse masses (D.4's depth masses,
    ``projection_masses``; fixed ends do not move). Corrections become velocity in full.
    Per edge, the second end's rows are gathered next to the first's (``PARTNER_*``), both
    solved there (the second's result in ``ACCUM3``), then the second's copied back; an edge
    left as it is writes its ends' positions back unchanged."""
    projection_masses(PS, PM, BI, topology, b, l0, l1)
    l1 = min(l1, LANES)   # a lane loop bounded by LANES vectorises (lanes.py)
    g0 = BI[b, bk.BI_G0]
    attribute, pairs = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_EDGE_PAIRS]
    for e in range(BI[b, bk.BI_EDGES]):
        ia = topology[pairs + 2 * e]
        ib = topology[pairs + 2 * e + 1]
        if (topology[attribute + ia] & MOVE) == 0 and (topology[attribute + ib] & MOVE) == 0:
            continue   # both ends fixed: w_a + w_b = 0
        ga = g0 + ia
        gb = g0 + ib
        for l in range(l0, l1):   # the second end's values next to the first's
            put3(PS, ga, st.PARTNER_POS, l, get3(PS, gb, st.NEXT_POS, l))
            put3(PS, ga, st.PARTNER_BASE, l, get3(PS, gb, st.STEP_BASIC_POS, l))
            put1(PS, ga, st.PARTNER_W, l, get1(PS, gb, st.PROJECTION_INVERSE_MASS, l))
        for l in range(l0, l1):
            wa = get1(PS, ga, st.PROJECTION_INVERSE_MASS, l)
            wb = get1(PS, ga, st.PARTNER_W, l)
            rest = v_length(v_sub(get3(PS, ga, st.STEP_BASIC_POS, l), get3(PS, ga, st.PARTNER_BASE, l)))
            pa = get3(PS, ga, st.NEXT_POS, l)
            pb = get3(PS, ga, st.PARTNER_POS, l)
            d = v_sub(pb, pa)
            length = v_length(d)
            keep = (wa + wb <= 0.0) | (length <= rest) | (length < 1e-12)   # no short-circuit: a select
            c = v_scale(d, (length - rest) / (length * (wa + wb)))   # discarded when kept
            put3(PS, ga, st.NEXT_POS, l, pa if keep else v_add(pa, v_scale(c, wa)))
            put3(PS, ga, st.ACCUM3, l, pb if keep else v_sub(pb, v_scale(c, wb)))
        for l in range(l0, l1):
            put3(PS, gb, st.NEXT_POS, l, get3(PS, ga, st.ACCUM3, l))


@kernel(forceinline=False)
def stretched_lanes(PS, TS, BI, topology, b, w):
    """``PROJECTION_NEEDED`` of lanes ``0 .. w - 1`` of block b: has the lane an edge with a moving
    end stretched by more than ``PROJECTION_THRESHOLD`` of its step-basic rest length (the
    condition under which ``edge_projection_lane`` solves)? Every lane side by side, so that
    the lane-by-lane projection runs only for the lanes that need it."""
    w = min(w, LANES)   # a lane loop bounded by LANES vectorises (lanes.py)
    g0 = BI[b, bk.BI_G0]
    attribute, pairs = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_EDGE_PAIRS]
    for l in range(w):
        put1(TS, b, st.PROJECTION_NEEDED, l, 0.0)
    for e in range(BI[b, bk.BI_EDGES]):
        ia = topology[pairs + 2 * e]
        ib = topology[pairs + 2 * e + 1]
        if (topology[attribute + ia] & MOVE) == 0 and (topology[attribute + ib] & MOVE) == 0:
            continue   # both ends fixed: not in the projection
        ga = g0 + ia
        gb = g0 + ib
        for l in range(w):
            rest = v_length(v_sub(get3(PS, ga, st.STEP_BASIC_POS, l), get3(PS, gb, st.STEP_BASIC_POS, l)))
            length = v_length(v_sub(get3(PS, gb, st.NEXT_POS, l), get3(PS, ga, st.NEXT_POS, l)))
            stretched = (length >= 1e-12) & (length > rest * (1.0 + PROJECTION_THRESHOLD))   # a select
            put1(TS, b, st.PROJECTION_NEEDED, l, 1.0 if stretched else get1(TS, b, st.PROJECTION_NEEDED, l))


@kernel
def has_cross_links(BI, topology, b):
    """Does block b's topology have a proxy edge that is not a parent link (a mesh cloth's
    horizontal links and triangle diagonals)? Line cloths are held exactly by FTL and skip the
    projection. The same for every lane (topology only)."""
    parent, pairs = BI[b, bk.BI_PARENT], BI[b, bk.BI_EDGE_PAIRS]
    for e in range(BI[b, bk.BI_EDGES]):
        ia = topology[pairs + 2 * e]
        ib = topology[pairs + 2 * e + 1]
        if topology[parent + ia] != ib and topology[parent + ib] != ia:
            return True
    return False


@kernel
def tangential(v, c):
    """v without its component along the unit (or zero) contact direction c."""
    return v_sub(v, v_scale(c, v_dot(v, c)))


@kernel(forceinline=False)
def edge_projection_lane(PS, PM, EDS, BI, topology, b, l, iterations, contacts):
    """Fast projection (Goldenthal et al. 2007) of the stretched proxy edges of lane l of
    block b, all at once, when one of them is stretched by more than ``PROJECTION_THRESHOLD``:
    one linearised solve of ``(J W S J^T + K) lambda = C`` over the edges at least
    ``1 - PROJECTION_SLACK`` times their step-basic rest length (C = max(length - rest, 0): the
    stretched ones are shortened, the others kept from stretching while their neighbours
    move; J the edges' unit directions, W D.4's depth inverse masses with fixed ends 0, K
    diagonal, ``(PROJECTION_COMPLIANCE + s / (1 - s)) (w_a + w_b)`` with s the edge's
    compression as a share of the slack: a shorter edge holds less, and nothing as it leaves
    the solve, so the result is continuous in the positions),
    by ``iterations`` Jacobi-preconditioned conjugate-gradient iterations, then
    ``x -= W S J^T lambda`` with lambda >= 0 (an edge only pulls). The correction becomes
    velocity in full. ``contacts``: S removes, for a particle that collision last pushed
    out of a collider this step, the component along that push (``PROJECTION_CONTACT``): it
    slides along the collider's supporting plane and its neighbours give way (a filtered
    solve, Baraff and Witkin 1998); otherwise S = I.

    Gauss-Seidel edge passes shorten an edge by moving its ends along it; the uniform
    expansion of a ring (a flared skirt) needs every particle to move inwards, which each
    pass reaches only through the small angle between neighbouring chords (the slowest mode
    of the ring's edges: 13 % of it per pass on a 12-strand ring). The solve couples every
    edge and removes that mode with the others (conjugate gradients converge in about
    sqrt(condition) iterations, and exactly in as many as the system has distinct
    eigenvalues). Returns whether it ran.

    Lane by lane (the active set and the iterations depend on the lane's state): per-particle
    values in ``PS`` (``PROJECTION_*``), per-edge ones in ``EDS`` (item = edge slot), the edges
    in the solve listed in ``EDGE_ACTIVE`` from the block's first edge slot."""
    projection_masses(PS, PM, BI, topology, b, l, l + 1)
    g0 = BI[b, bk.BI_G0]
    n = BI[b, bk.BI_N]
    pairs = BI[b, bk.BI_EDGE_PAIRS]
    s0 = BI[b, bk.BI_EDGE0]
    count = 0   # the edges in the solve, listed in EDGE_ACTIVE of slots s0 .. s0 + count - 1
    stretched = False
    rz = 0.0
    for e in range(BI[b, bk.BI_EDGES]):
        ga = g0 + topology[pairs + 2 * e]
        gb = g0 + topology[pairs + 2 * e + 1]
        s = s0 + e
        wa = get1(PS, ga, st.PROJECTION_INVERSE_MASS, l)
        wb = get1(PS, gb, st.PROJECTION_INVERSE_MASS, l)
        if wa + wb <= 0.0:
            continue
        rest = v_length(v_sub(get3(PS, ga, st.STEP_BASIC_POS, l), get3(PS, gb, st.STEP_BASIC_POS, l)))
        d = v_sub(get3(PS, gb, st.NEXT_POS, l), get3(PS, ga, st.NEXT_POS, l))
        length = v_length(d)
        slack = (rest - length) / (rest * PROJECTION_SLACK) if rest > 0.0 else 0.0
        if slack >= 1.0 or length < 1e-12:
            continue
        normal = v_scale(d, 1.0 / length)
        c = max(length - rest, 0.0)
        stretched = stretched or length > rest * (1.0 + PROJECTION_THRESHOLD)
        # a shorter edge is kept from stretching less the shorter it is, and not at all at
        # 1 - PROJECTION_SLACK of its rest: its compliance grows from 0 to infinity on the way
        compliance = (PROJECTION_COMPLIANCE + (slack / (1.0 - slack) if slack > 0.0 else 0.0)) * (wa + wb)
        put1(EDS, s, st.EDGE_COMPLIANCE, l, compliance)
        diagonal = compliance
        if contacts:
            diagonal += wa * v_length_sq(tangential(normal, get3(PS, ga, st.PROJECTION_CONTACT, l))) \
                + wb * v_length_sq(tangential(normal, get3(PS, gb, st.PROJECTION_CONTACT, l)))
        else:
            diagonal += wa + wb
        put1(EDS, s0 + count, st.EDGE_ACTIVE, l, float(e))
        count += 1
        put3(EDS, s, st.EDGE_NORMAL, l, normal)
        put1(EDS, s, st.EDGE_DIAGONAL, l, diagonal)
        put1(EDS, s, st.EDGE_LAMBDA, l, 0.0)
        put1(EDS, s, st.EDGE_RESIDUAL, l, c)
        put1(EDS, s, st.EDGE_DIRECTION, l, c / diagonal)
        rz += c * c / diagonal
    if not stretched:
        return False
    stop = rz * PROJECTION_TOLERANCE * PROJECTION_TOLERANCE
    beta = 0.0
    for iteration in range(iterations):
        for j in range(n):
            put3(PS, g0 + j, st.PROJECTION_GATHER, l, ZERO3)
        for i in range(count):   # the search direction (after the first), and W S J^T of it
            e = int(get1(EDS, s0 + i, st.EDGE_ACTIVE, l))
            s = s0 + e
            if iteration > 0:
                put1(EDS, s, st.EDGE_DIRECTION, l,
                     get1(EDS, s, st.EDGE_RESIDUAL, l) / get1(EDS, s, st.EDGE_DIAGONAL, l)
                     + beta * get1(EDS, s, st.EDGE_DIRECTION, l))
            de = get1(EDS, s, st.EDGE_DIRECTION, l)
            ga = g0 + topology[pairs + 2 * e]
            gb = g0 + topology[pairs + 2 * e + 1]
            normal = get3(EDS, s, st.EDGE_NORMAL, l)
            wa = get1(PS, ga, st.PROJECTION_INVERSE_MASS, l)
            wb = get1(PS, gb, st.PROJECTION_INVERSE_MASS, l)
            sum_a = get3(PS, ga, st.PROJECTION_GATHER, l)
            put3(PS, ga, st.PROJECTION_GATHER, l, v_sub(sum_a, v_scale(normal, wa * de)))
            sum_b = get3(PS, gb, st.PROJECTION_GATHER, l)
            put3(PS, gb, st.PROJECTION_GATHER, l, v_add(sum_b, v_scale(normal, wb * de)))
        if contacts:
            for j in range(n):
                g = g0 + j
                put3(PS, g, st.PROJECTION_GATHER, l, tangential(get3(PS, g, st.PROJECTION_GATHER, l),
                                                                get3(PS, g, st.PROJECTION_CONTACT, l)))
        dad = 0.0
        for i in range(count):
            e = int(get1(EDS, s0 + i, st.EDGE_ACTIVE, l))
            s = s0 + e
            de = get1(EDS, s, st.EDGE_DIRECTION, l)
            ga = g0 + topology[pairs + 2 * e]
            gb = g0 + topology[pairs + 2 * e + 1]
            ad = v_dot(get3(EDS, s, st.EDGE_NORMAL, l),
                       v_sub(get3(PS, gb, st.PROJECTION_GATHER, l), get3(PS, ga, st.PROJECTION_GATHER, l))) \
                + get1(EDS, s, st.EDGE_COMPLIANCE, l) * de
            put1(EDS, s, st.EDGE_PRODUCT, l, ad)
            dad += de * ad
        if dad <= 0.0:
            break
        alpha = rz / dad
        rz_next = 0.0
        for i in range(count):
            s = s0 + int(get1(EDS, s0 + i, st.EDGE_ACTIVE, l))
            lam = get1(EDS, s, st.EDGE_LAMBDA, l) + alpha * get1(EDS, s, st.EDGE_DIRECTION, l)
            put1(EDS, s, st.EDGE_LAMBDA, l, lam)
            r = get1(EDS, s, st.EDGE_RESIDUAL, l) - alpha * get1(EDS, s, st.EDGE_PRODUCT, l)
            put1(EDS, s, st.EDGE_RESIDUAL, l, r)
            rz_next += r * r / get1(EDS, s, st.EDGE_DIAGONAL, l)
        if rz_next <= stop:
            break
        beta = rz_next / rz
        rz = rz_next
    for i in range(count):
        e = int(get1(EDS, s0 + i, st.EDGE_ACTIVE, l))
        s = s0 + e
        lam = get1(EDS, s, st.EDGE_LAMBDA, l)
        if lam <= 0.0:
            continue
        ga = g0 + topology[pairs + 2 * e]
        gb = g0 + topology[pairs + 2 * e + 1]
        normal = get3(EDS, s, st.EDGE_NORMAL, l)
        da = v_scale(normal, get1(PS, ga, st.PROJECTION_INVERSE_MASS, l) * lam)
        db = v_scale(normal, get1(PS, gb, st.PROJECTION_INVERSE_MASS, l) * lam)
        if contacts:
            da = tangential(da, get3(PS, ga, st.PROJECTION_CONTACT, l))
            db = tangential(db, get3(PS, gb, st.PROJECTION_CONTACT, l))
        put3(PS, ga, st.NEXT_POS, l, v_add(get3(PS, ga, st.NEXT_POS, l), da))
        put3(PS, gb, st.NEXT_POS, l, v_sub(get3(PS, gb, st.NEXT_POS, l), db))
    return True
