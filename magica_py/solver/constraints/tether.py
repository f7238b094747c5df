"""Tether (ref §D.3): keep each moving particle between (1 - compression) and 1.03 times its
rest distance to its root. Only the particle moves; the root is infinitely heavy."""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, saturate, store3, v_add, v_length, v_scale, v_sub

MOVE = 0x02
STRETCH_LIMIT = 0.03          # TetherStretchLimit
STIFFNESS_WIDTH = 0.3         # TetherStiffnessWidth
COMPRESSION_STIFFNESS = 1.0   # TetherCompressionStiffness
STRETCH_STIFFNESS = 1.0       # TetherStretchStiffness
VELOCITY_ATTENUATION = 0.7    # Tether{Compression,Stretch}VelocityAttenuation


@kernel
def solve_tether(position, root_position, rest_length, compression_limit):
    """Correction of ``position`` towards the allowed band around ``rest_length`` (zero if inside)."""
    v = v_sub(root_position, position)
    length = v_length(v)
    if length < 1e-8 or rest_length == 0.0:
        return (0.0, 0.0, 0.0)
    ratio = length / rest_length
    stretch_limit = 1.0 + STRETCH_LIMIT
    if ratio < compression_limit:
        d = length - compression_limit * rest_length
        k = saturate((compression_limit - ratio) / STIFFNESS_WIDTH) * COMPRESSION_STIFFNESS
    elif ratio > stretch_limit:
        d = length - stretch_limit * rest_length
        k = saturate((ratio - stretch_limit) / STIFFNESS_WIDTH) * STRETCH_STIFFNESS
    else:
        return (0.0, 0.0, 0.0)
    return v_scale(v, d * k / length)


@kernel
def tether_team(m, ps, prm, team, attenuation):
    """D.3 over one team's moving particles; ``attenuation`` is the per-step velocity attenuation."""
    start = m.team_particle_start[team]
    compression_limit = 1.0 - prm.tether_compression[team]
    for p in range(start, start + m.team_particle_count[team]):
        if (m.attribute[p] & MOVE) == 0:
            continue
        r = m.root_index[p]
        if r < 0:
            continue
        rest = v_length(v_sub(load3(ps.step_basic_pos, p), load3(ps.step_basic_pos, r)))
        delta = solve_tether(load3(ps.next_pos, p), load3(ps.next_pos, r), rest, compression_limit)
        store3(ps.next_pos, p, v_add(load3(ps.next_pos, p), delta))
        store3(ps.velocity_pos, p, v_add(load3(ps.velocity_pos, p), v_scale(delta, attenuation)))
