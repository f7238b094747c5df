"""Tether (docs/solver.md §D.3): keep each moving particle between (1 - compression) and 1.03 times its
rest distance to its root. Only the particle moves; the root is infinitely heavy.
``tether_block`` runs one block through the per-element function ``solve_tether``: the root's
position gathered next to each particle (``PARTNER_*`` rows), then solved across the lanes."""
from __future__ import annotations

import numpy as np

from magica_py.build.proxy import MOVE
from magica_py.jit import kernel
from magica_py.kernels.math3d import saturate, v_add, v_length, v_scale, v_sub
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import get3, put3
from magica_py.solver.parameters import PRM_QUALITY, PRM_RATE_MODE, PRM_TETHER_COMPRESSION, step_rate

STRETCH_LIMIT = 0.03          # TetherStretchLimit
STIFFNESS_WIDTH = 0.3         # TetherStiffnessWidth
COMPRESSION_STIFFNESS = 1.0   # TetherCompressionStiffness
STRETCH_STIFFNESS = 1.0       # TetherStretchStiffness
VELOCITY_ATTENUATION = 0.7    # Tether{Compression,Stretch}VelocityAttenuation
ZERO3 = (0.0, 0.0, 0.0)


@kernel(inline="always")
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
        k = step_rate(k, frequency_ratio, 1.0, np.int64(1))
    corr = v_scale(v, d * k / length)
    active = (compressed | stretched) & (length >= 1e-8) & (rest_length != 0.0)
    return corr if active else ZERO3


@kernel
def gather_partner_step_pose(PS, g, gp, w):
    """Particle slot gp's predicted position and step-basic position copied next to slot g's
    (``PARTNER_POS``, ``PARTNER_BASE``) for lanes 0..w, so the solving loop reads one item:
    the tether's root, quality mode's tight tether and follow-the-leader parent."""
    for l in range(w):
        put3(PS, g, st.PARTNER_POS, l, get3(PS, gp, st.NEXT_POS, l))
        put3(PS, g, st.PARTNER_BASE, l, get3(PS, gp, st.STEP_BASIC_POS, l))


@kernel(forceinline=False)
def tether_block(PS, P, BI, topology, b, attenuation, frequency_ratio):
    """D.3 over block b's moving particles; ``attenuation`` is the per-step velocity attenuation.
    Frequency-consistent mode (not quality mode, which keeps MagicaCloth2's tether here) converts
    the correction's per-step share by the step (``solve_tether``)."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    attribute, root_index = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_ROOT_INDEX]
    n = BI[b, bk.BI_N]
    # every value of P read before the first branch (docs/tech-notes.md §10)
    compression_limit = 1.0 - P[b, PRM_TETHER_COMPRESSION]
    rate_mode, quality = P[b, PRM_RATE_MODE], P[b, PRM_QUALITY]
    ratio = frequency_ratio if (rate_mode != 0.0 and quality == 0.0) else 1.0
    for j in range(n):
        if (topology[attribute + j] & MOVE) == 0:
            continue
        r = topology[root_index + j]
        if r < 0:
            continue
        g = g0 + j
        gr = g0 + r
        gather_partner_step_pose(PS, g, gr, w)   # the root's values next to the particle's
        # at 90 Hz or in MagicaCloth2 mode the rate conversion (a pow, an opaque call that
        # stops the vectoriser) is left out of the compiled loop by the constant argument
        if ratio == 1.0:
            tether_lanes(PS, g, w, compression_limit, 1.0, attenuation)
        else:
            tether_lanes(PS, g, w, compression_limit, ratio, attenuation)


@kernel
def tether_lanes(PS, g, w, compression_limit, ratio, attenuation):
    """D.3 of particle slot g, lanes 0..w, its root's rows gathered next to it."""
    for l in range(w):
        p_pos = get3(PS, g, st.NEXT_POS, l)
        rest = v_length(v_sub(get3(PS, g, st.STEP_BASIC_POS, l), get3(PS, g, st.PARTNER_BASE, l)))
        delta = solve_tether(p_pos, get3(PS, g, st.PARTNER_POS, l), rest, compression_limit, ratio)
        put3(PS, g, st.NEXT_POS, l, v_add(p_pos, delta))
        put3(PS, g, st.VELOCITY_POS, l, v_add(get3(PS, g, st.VELOCITY_POS, l), v_scale(delta, attenuation)))
