"""Transform data and write-back (docs/solver.md §E.4).

World transform data: ``T_pos = position``, ``T_rot = rotation * v2t``. Fixed bones get their
world rotation written (as a local rotation under the parent's current world rotation); moving
bones with a parent particle get local position and rotation relative to the parent's written
pose, divided by the parent's lossy scale. Invalid bones are untouched. A team with any
non-finite value is not written at all (guard).
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, store3, store4, q_inverse, q_mul, q_normalize, q_rotate, v_sub
from reference_solver.solver.rotations import q_normalize_or_identity

FIXED = 0x01
MOVE = 0x02


@kernel
def finite3(v):
    return math.isfinite(v[0]) & math.isfinite(v[1]) & math.isfinite(v[2])


@kernel
def finite4(q):
    return math.isfinite(q[0]) & math.isfinite(q[1]) & math.isfinite(q[2]) & math.isfinite(q[3])


@kernel(inline="always")
def bone_rotation(rotation, v2t):
    """E.4: the bone's world rotation from the particle's rotation and its v2t."""
    return q_normalize_or_identity(q_mul(rotation, v2t))


@kernel
def transform_data_team(m, ps, team):
    """World transform data of every bone of one team; returns False if any value is non-finite.

    Vectorised over the team's bones (flat rows, selects, the verdict AND-ed)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_team_particle_count = m.team_particle_count
    position, rotation, v2t = ps.position, ps.rotation, m.vertex_to_transform_rotation
    transform_position, transform_rotation = ps.transform_position, ps.transform_rotation
    ok = True
    first = np.uint64(m.team_particle_start[team])
    for j in range(m_team_particle_count[team]):
        p = first + np.uint64(j)
        pos = load3(position, p)
        rot = bone_rotation(load4(rotation, p), load4(v2t, p))
        store3(transform_position, p, pos)
        store4(transform_rotation, p, rot)
        ok = ok & finite3(pos) & finite4(rot)
    return ok


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


@kernel
def write_transforms_team(m, ps, team, parent_node, world_rotation, lossy_scale,
                          local_position, local_rotation):
    """Write one team's bones into the hierarchy's local pose arrays.

    Scalar: the writes are scatters (through transform_index) of 3- and 4-value rows, which
    LLVM's vectoriser cannot check for overlap, so the branches stay."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_team_particle_count = m.team_particle_count
    # arrays as locals and flat rows: through the tables their pointers would be reloaded
    # after every store (the stores may alias the tables as far as LLVM knows)
    attribute, node_of, parent_of = m.attribute, m.transform_index, m.parent
    transform_position, transform_rotation = ps.transform_position, ps.transform_rotation
    world_rot, scale = world_rotation, lossy_scale
    out_position, out_rotation = local_position, local_rotation
    first = np.uint64(m.team_particle_start[team])
    for j in range(m_team_particle_count[team]):
        p = first + np.uint64(j)
        attr = attribute[p]
        node = np.uint64(node_of[p])
        if (attr & MOVE) != 0:
            pp = parent_of[p]
            if pp < 0:
                continue
            ppu = np.uint64(pp)
            pnode = np.uint64(node_of[ppu])
            lp, lq = moving_bone_local(load4(transform_rotation, ppu),
                                       load3(transform_position, ppu),
                                       load4(transform_rotation, p),
                                       load3(transform_position, p), load3(scale, pnode))
            store3(out_position, node, lp)
            store4(out_rotation, node, lq)
        elif (attr & FIXED) != 0:
            parent = parent_node[node]
            rot = load4(transform_rotation, p)
            if parent >= 0:
                store4(out_rotation, node,
               fixed_bone_local(rot, load4(world_rot, np.uint64(parent)), True))
            else:
                store4(out_rotation, node, fixed_bone_local(rot, rot, False))
