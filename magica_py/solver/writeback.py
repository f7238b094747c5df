"""Transform data and write-back (docs/solver.md §E.4).

World transform data: ``T_pos = position``, ``T_rot = rotation * v2t``. Fixed bones get their
world rotation written (as a local rotation under the parent's current world rotation); moving
bones with a parent particle get local position and rotation relative to the parent's written
pose, divided by the parent's lossy scale. Invalid bones are untouched. A team with any
non-finite value is not written at all (guard).
"""
from __future__ import annotations

import math

from magica_py.build.proxy import FIXED, MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import q_inverse, q_mul, q_normalize, q_normalize_select, q_rotate, v_sub
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import get1, get3, get4, put1, put3, put4


@kernel(inline="always")
def finite3(v):
    return math.isfinite(v[0]) & math.isfinite(v[1]) & math.isfinite(v[2])


@kernel(inline="always")
def finite4(q):
    return math.isfinite(q[0]) & math.isfinite(q[1]) & math.isfinite(q[2]) & math.isfinite(q[3])


@kernel(inline="always")
def bone_rotation(rotation, v2t):
    """E.4: the bone's world rotation from the particle's rotation and its v2t."""
    return q_normalize_select(q_mul(rotation, v2t))


@kernel(inline="always")
def moving_bone_local(parent_rotation, parent_position, rotation, position, parent_scale):
    """E.4: local (position, rotation) of a moving bone under its parent particle's bone pose,
    the position divided by the parent's lossy scale (0 where a scale component is 0)."""
    iq = q_inverse(parent_rotation)
    lp = q_rotate(iq, v_sub(position, parent_position))
    s0, s1, s2 = parent_scale
    local = (lp[0] / s0 if s0 != 0.0 else 0.0, lp[1] / s1 if s1 != 0.0 else 0.0, lp[2] / s2 if s2 != 0.0 else 0.0)
    return local, q_normalize(q_mul(iq, rotation))


@kernel(inline="always")
def fixed_bone_local(rotation, parent_world_rotation, has_parent):
    """E.4: local rotation of a fixed bone under its parent node's current world rotation."""
    if has_parent:
        rotation = q_mul(q_inverse(parent_world_rotation), rotation)
    return q_normalize(rotation)


@kernel(forceinline=False)
def transform_block(PS, PM, TS, BI, PT, topology, b, parent_node, world_rotation, lossy_scale):
    """E.4's world transform data of every bone of block b, every lane side by side, and the
    local pose each bone will be written with (``LOCAL_OUT_*``): a moving bone's relative to
    its parent particle's transform, a fixed bone's rotation under its parent node's current
    world rotation (the hierarchy's values it needs gathered next to it first). Each lane's
    ``TRANSFORM_OK`` is 1 when every value of its transform data is finite."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute, parent = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_PARENT]
    for l in range(w):
        put1(TS, b, st.TRANSFORM_OK, l, 1.0)
    for j in range(BI[b, bk.BI_N]):
        g = g0 + j
        for l in range(w):
            pos = get3(PS, g, st.POSITION, l)
            rot = bone_rotation(get4(PS, g, st.ROTATION, l), get4(PM, g, bk.VERTEX_TO_TRANSFORM_ROTATION, l))
            put3(PS, g, st.TRANSFORM_POSITION, l, pos)
            put4(PS, g, st.TRANSFORM_ROTATION, l, rot)
            ok = get1(TS, b, st.TRANSFORM_OK, l) != 0.0
            put1(TS, b, st.TRANSFORM_OK, l, 1.0 if (ok & finite3(pos) & finite4(rot)) else 0.0)
    for j in range(BI[b, bk.BI_N]):
        attr = topology[attribute + j]
        g = g0 + j
        if (attr & MOVE) != 0:
            pp = topology[parent + j]
            if pp < 0:
                continue
            gp = g0 + pp
            for l in range(w):   # the parent's transform and its node's scale next to the bone
                node = PT[gp, l]
                put3(PS, g, st.PARTNER_POS, l, get3(PS, gp, st.TRANSFORM_POSITION, l))
                put4(PS, g, st.PARENT_ROTATION, l, get4(PS, gp, st.TRANSFORM_ROTATION, l))
                put3(PS, g, st.PARTNER_BASE, l, (lossy_scale[node, 0], lossy_scale[node, 1], lossy_scale[node, 2]))
            for l in range(w):
                lp, lq = moving_bone_local(get4(PS, g, st.PARENT_ROTATION, l), get3(PS, g, st.PARTNER_POS, l),
                                           get4(PS, g, st.TRANSFORM_ROTATION, l), get3(PS, g, st.TRANSFORM_POSITION, l),
                                           get3(PS, g, st.PARTNER_BASE, l))
                put3(PS, g, st.LOCAL_OUT_POSITION, l, lp)
                put4(PS, g, st.LOCAL_OUT_ROTATION, l, lq)
        elif (attr & FIXED) != 0:
            for l in range(w):   # the parent node's world rotation next to the bone (identity: no parent)
                up = parent_node[PT[g, l]]
                q = (world_rotation[up, 0], world_rotation[up, 1], world_rotation[up, 2], world_rotation[up, 3]) \
                    if up >= 0 else (0.0, 0.0, 0.0, 1.0)
                put4(PS, g, st.PARENT_ROTATION, l, q)
                PS[g, st.PARENT_HAS_NODE + l] = 1.0 if up >= 0 else 0.0
            for l in range(w):
                rot = get4(PS, g, st.TRANSFORM_ROTATION, l)
                under = fixed_bone_local(rot, get4(PS, g, st.PARENT_ROTATION, l), True)
                alone = fixed_bone_local(rot, rot, False)
                put4(PS, g, st.LOCAL_OUT_ROTATION, l, under if PS[g, st.PARENT_HAS_NODE + l] != 0.0 else alone)


@kernel(forceinline=False)
def write_transforms_block(PS, TS, TI, BI, PT, topology, b, w, local_position, local_rotation):
    """Write the bones of every active lane of block b whose transform data is finite
    (``TRANSFORM_OK``; ``transform_block``'s local poses) into the hierarchy's local pose
    arrays: a scatter through the bones' hierarchy nodes; invalid bones and a moving bone
    without a parent particle are left alone. The lane loop is here so that numba counts the
    array arguments once a block."""
    g0 = BI[b, bk.BI_G0]
    attribute, parent = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_PARENT]
    for l in range(w):
        if TI[b, bk.TI_TEAM + l] < 0 or get1(TS, b, st.ACTIVE, l) == 0.0 or get1(TS, b, st.TRANSFORM_OK, l) == 0.0:
            continue
        for j in range(BI[b, bk.BI_N]):
            attr = topology[attribute + j]
            g = g0 + j
            node = PT[g, l]
            if (attr & MOVE) != 0:
                if topology[parent + j] < 0:
                    continue
                lp = get3(PS, g, st.LOCAL_OUT_POSITION, l)
                local_position[node, 0] = lp[0]
                local_position[node, 1] = lp[1]
                local_position[node, 2] = lp[2]
            elif (attr & FIXED) == 0:
                continue
            lq = get4(PS, g, st.LOCAL_OUT_ROTATION, l)
            for c in range(4):
                local_rotation[node, c] = lq[c]
