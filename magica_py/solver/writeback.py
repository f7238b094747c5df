"""Transform data and write-back (ref §E.4).

World transform data: ``T_pos = position``, ``T_rot = rotation * v2t``. Fixed bones get their
world rotation written (as a local rotation under the parent's current world rotation); moving
bones with a parent particle get local position and rotation relative to the parent's written
pose, divided by the parent's lossy scale. Invalid bones are untouched. A team with any
non-finite value is not written at all (guard).
"""
from __future__ import annotations

import math

from magica_py.jit import kernel
from magica_py.kernels.math3d import (
    load3, load4, q_inverse, q_mul, q_normalize, q_rotate, store3, store4, v_sub,
)

FIXED = 0x01
MOVE = 0x02


@kernel
def transform_data_team(m, ps, team):
    """World transform data of every bone of one team; returns False if any value is non-finite."""
    ok = True
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        pos = load3(ps.position, p)
        rot = q_normalize(q_mul(load4(ps.rotation, p), load4(m.vertex_to_transform_rotation, p)))
        store3(ps.transform_position, p, pos)
        store4(ps.transform_rotation, p, rot)
        for c in range(3):
            if not math.isfinite(pos[c]):
                ok = False
        for c in range(4):
            if not math.isfinite(rot[c]):
                ok = False
    return ok


@kernel
def write_transforms_team(m, ps, team, parent_node, world_rotation, lossy_scale,
                          local_position, local_rotation):
    """Write one team's bones into the hierarchy's local pose arrays."""
    start = m.team_particle_start[team]
    for p in range(start, start + m.team_particle_count[team]):
        attr = m.attribute[p]
        node = m.transform_index[p]
        if (attr & MOVE) != 0:
            pp = m.parent[p]
            if pp < 0:
                continue
            iq = q_inverse(load4(ps.transform_rotation, pp))
            lp = q_rotate(iq, v_sub(load3(ps.transform_position, p), load3(ps.transform_position, pp)))
            pnode = m.transform_index[pp]
            for c in range(3):
                s = lossy_scale[pnode, c]
                local_position[node, c] = lp[c] / s if s != 0.0 else 0.0
            store4(local_rotation, node, q_normalize(q_mul(iq, load4(ps.transform_rotation, p))))
        elif (attr & FIXED) != 0:
            parent = parent_node[node]
            rot = load4(ps.transform_rotation, p)
            if parent >= 0:
                rot = q_mul(q_inverse(load4(world_rotation, parent)), rot)
            store4(local_rotation, node, q_normalize(rot))
