"""Tether (docs/solver.md §D.3): keep each moving particle between (1 - compression) and 1.03 times its
rest distance to its root. Only the particle moves; the root is infinitely heavy.
``tether_team`` runs one team through the per-element function ``solve_tether``."""
from __future__ import annotations


from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, saturate, store3, v_add, v_length, v_scale, v_sub
from reference_solver.solver.parameters import step_rate

MOVE = 0x02
STRETCH_LIMIT = 0.03          # TetherStretchLimit
STIFFNESS_WIDTH = 0.3         # TetherStiffnessWidth
COMPRESSION_STIFFNESS = 1.0   # TetherCompressionStiffness
STRETCH_STIFFNESS = 1.0       # TetherStretchStiffness
VELOCITY_ATTENUATION = 0.7    # Tether{Compression,Stretch}VelocityAttenuation
ZERO3 = (0.0, 0.0, 0.0)


@kernel
def solve_tether(position, root_position, rest_length, compression_limit, frequency_ratio=1.0):
    """Correction of ``position`` towards the allowed band around ``rest_length``: zero inside
    the band, when the particle sits on its root (< 1e-8) or when the rest length is zero.
    The share of the excess removed, ``k = saturate(excess / 0.3)``, is a per-step rate:
    ``frequency_ratio`` (90/f) != 1 converts it as one, ``1 - (1 - k)^(90/f)``
    (frequency-consistent mode; 1: MagicaCloth2's k). Branch-free (selects, no branches)."""
    v = v_sub(root_position, position)
    length = v_length(v)
    ratio = length / rest_length
    stretch_limit = 1.0 + STRETCH_LIMIT
    compressed = ratio < compression_limit
    stretched = ratio > stretch_limit
    # the side's operands are selected before the arithmetic: one division for both sides
    limit = compression_limit if compressed else stretch_limit
    excess = (compression_limit - ratio) if compressed else (ratio - stretch_limit)
    d = length - limit * rest_length
    k = saturate(excess / STIFFNESS_WIDTH) * (COMPRESSION_STIFFNESS if compressed else STRETCH_STIFFNESS)
    if frequency_ratio != 1.0:
        k = step_rate(k, frequency_ratio, 1.0, 1)
    corr = v_scale(v, d * k / length)
    active = (compressed | stretched) & (length >= 1e-8) & (rest_length != 0.0)
    return corr if active else ZERO3


@kernel
def tether_team(m, ps, prm, team, attenuation, frequency_ratio):
    """D.3 over one team's moving particles; ``attenuation`` is the per-step velocity attenuation.
    Frequency-consistent mode (not quality mode, which keeps MagicaCloth2's tether here) converts
    the correction's per-step share by the step (``solve_tether``)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_root_index, m_team_particle_count = m.attribute, m.root_index, m.team_particle_count
    ps_next_pos, ps_step_basic_pos, ps_velocity_pos = ps.next_pos, ps.step_basic_pos, ps.velocity_pos
    start = m.team_particle_start[team]
    compression_limit = 1.0 - prm.tether_compression[team]
    ratio = frequency_ratio if (prm.rate_mode[team] != 0 and prm.quality[team] == 0) else 1.0
    for p in range(start, start + m_team_particle_count[team]):
        if (m_attribute[p] & MOVE) == 0:
            continue
        r = m_root_index[p]
        if r < 0:
            continue
        rest = v_length(v_sub(load3(ps_step_basic_pos, p), load3(ps_step_basic_pos, r)))
        delta = solve_tether(load3(ps_next_pos, p), load3(ps_next_pos, r), rest, compression_limit, ratio)
        store3(ps_next_pos, p, v_add(load3(ps_next_pos, p), delta))
        store3(ps_velocity_pos, p, v_add(load3(ps_velocity_pos, p), v_scale(delta, attenuation)))


