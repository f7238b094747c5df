"""Quality mode's contact speed limit, after D.10 (``docs/quality-mode.md``, *Contact speed*).

MagicaCloth2's contact friction (D.10) is weak and acts on the velocity of the particle, not
on its velocity relative to the body: a strand that arrives on a body part which has just
stopped (the end of a backflip, a roll) slides over it at the particle speed limit, 4 m/s,
and a strand dragged by a fast body part is not held to it. Quality mode adds a saturating
kinetic friction: at the end of a step, a moving particle within the contact range of a
collider (its sphere within one particle radius of the surface, D.8's friction range) keeps
at most ``solver.contact_speed_limit`` (m/s, times the cloth's scale) of velocity relative to
the body point under it:

    v' = v_body + clamp_length(v - v_body, limit)

then the particle speed limit again. ``v_body`` is the rigid velocity of the nearest
collider's body at the particle over this step: the point fixed to the collider that is at
the particle now, where it was at the collider's previous-step pose (after the local inertia
shift, the frame the particle's own velocity is in), divided by the step. The limit touches
only the velocity carried to the next step (``VELOCITY``), never a position, so it cannot
push a particle into a collider, and only particles faster than the body by more than the
limit. Faithful mode never calls this module (``PRM_CONTACT_SPEED_LIMIT`` is -1 there).

``contact_speed_block`` runs one block: per particle, per collider slot, the lanes side by
side (the nearest collider in range and its body velocity in scratch rows), then each lane's
clamp.
"""
from __future__ import annotations

from magica_py.build.proxy import DISABLE_COLLISION, MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import clamp_length, q_inverse, q_rotate, v_add, v_dot, v_length, v_scale, v_sub
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.constraints.collision import FAR, PLANE, particle_radius
from magica_py.solver.lanes import get1, get3, get4, put1, put3
from magica_py.solver.parameters import PRM_CONTACT_SPEED_LIMIT, PRM_PARTICLE_SPEED_LIMIT
from magica_py.solver.quality import step_axis_point


@kernel
def surface_gap(CS, k, l, shape, x, r):
    """Gap (m) between the particle sphere (x, r) and collider slot k of lane l at its pose of
    this step (``START_NEW`` / ``END_NEW``); negative inside."""
    if shape == PLANE:
        return v_dot(v_sub(x, get3(CS, k, st.START_NEW, l)), get3(CS, k, st.PLANE_NORMAL, l)) - r
    c, radius = step_axis_point(CS, k, l, shape, x)
    return v_length(v_sub(x, c)) - radius - r


@kernel
def body_point_velocity(now_pos, now_rot, old_pos, old_rot, x, dt):
    """Velocity (m/s) over a step of the point of a rigid body that is at x at the body's pose
    (now_pos, now_rot): x minus where that point was at (old_pos, old_rot), over dt."""
    local = q_rotate(q_inverse(now_rot), v_sub(x, now_pos))
    was = v_add(old_pos, q_rotate(old_rot, local))
    return v_scale(v_sub(x, was), 1.0 / dt)


@kernel
def contact_velocity(v, body, weight, limit, speed_limit):
    """A particle's carried velocity v (already times the stabilisation weight ``weight``)
    with its part relative to the body velocity ``body`` clamped to ``limit`` (both scaled by
    the weight, as D.10 scales the velocity), then the particle speed limit (``speed_limit``
    m/s, < 0: none) again."""
    carried = v_scale(body, weight)
    out = v_add(carried, clamp_length(v_sub(v, carried), limit * weight))
    return clamp_length(out, speed_limit * weight) if speed_limit >= 0.0 else out


@kernel(forceinline=False)
def contact_speed_block(PS, PP, TS, CS, P, BI, topology, b, dt):
    """The contact speed limit over block b's moving, colliding particles (module docstring),
    after ``end_step_block``: ``OLD_POS`` is the step's final position, ``VELOCITY`` the
    carried velocity."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute = BI[b, bk.BI_ATTRIBUTE]
    c0 = BI[b, bk.BI_COLLIDER0]
    shapes = BI[b, bk.BI_COLLIDER_SHAPE]
    limit = P[b, PRM_CONTACT_SPEED_LIMIT]
    speed_limit = P[b, PRM_PARTICLE_SPEED_LIMIT]
    z = (0.0, 0.0, 0.0)
    for j in range(BI[b, bk.BI_N]):
        attr = topology[attribute + j]
        if (attr & MOVE) == 0 or (attr & DISABLE_COLLISION) != 0:
            continue
        g = g0 + j
        for l in range(w):
            put1(PS, g, st.CONTACT_MIN_DIST, l, FAR)
            put3(PS, g, st.CONTACT_BODY_VELOCITY, l, z)
        for c in range(BI[b, bk.BI_COLLIDERS]):
            k = c0 + c
            shape = topology[shapes + c]
            for l in range(w):
                scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)
                r = particle_radius(get1(PP, g, bk.CURVE_RADIUS, l), scale)
                x = get3(PS, g, st.OLD_POS, l)
                gap = surface_gap(CS, k, l, shape, x, r)
                # selects, not branches (and no short-circuit): the lane loop vectorises
                min_dist = get1(PS, g, st.CONTACT_MIN_DIST, l)
                nearest = (gap <= r) & (gap < min_dist) & (get1(CS, k, st.SCALE_SUSPEND, l) == 0.0)
                body = body_point_velocity(get3(CS, k, st.NOW_POS, l), get4(CS, k, st.NOW_ROT, l),
                                           get3(CS, k, st.C_OLD_POS, l), get4(CS, k, st.C_OLD_ROT, l), x, dt)
                put1(PS, g, st.CONTACT_MIN_DIST, l, gap if nearest else min_dist)
                put3(PS, g, st.CONTACT_BODY_VELOCITY, l, body if nearest else get3(PS, g, st.CONTACT_BODY_VELOCITY, l))
        for l in range(w):
            scale = get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l)
            v = get3(PS, g, st.VELOCITY, l)
            limited = contact_velocity(v, get3(PS, g, st.CONTACT_BODY_VELOCITY, l), get1(TS, b, st.VELOCITY_WEIGHT, l),
                                       limit * scale, speed_limit * scale if speed_limit >= 0.0 else -1.0)
            put3(PS, g, st.VELOCITY, l, limited if get1(PS, g, st.CONTACT_MIN_DIST, l) < FAR else v)
