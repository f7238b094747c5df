"""The velocity attenuations of one step's constraints (docs/solver.md §D.3-§D.9), read by the
step (``frame.run_step``).

Each is the 90 Hz value converted to the step size by the team's rate mode, then by quality
mode where it applies (``quality.py``, which gives the same conversions):

* MagicaCloth2 mode (``rate_mode: magica``): the 90 Hz value as is;
* frequency-consistent mode: the hard limits' attenuations (tether 0.7, angle limit 0.9,
  motion 0.95: the share of the normal velocity that survives a step in which the limit
  removes a penetration) as per-step retentions, ``attn^(90/f)`` (``step_keep``); the share
  of angle restoration's correction that becomes velocity, ``1 - attn``, linearly in the step,
  ``(1 - attn) 90/f`` (``step_share``: the correction is itself about proportional to the
  step); distance's 0.3 as a rate, ``1 - 0.7^(90/f)`` (``step_rate``). All exact at 90 Hz.
"""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.solver.constraints.angle import LIMIT_ATTENUATION
from magica_py.solver.constraints.distance import VELOCITY_ATTENUATION as DISTANCE_ATTENUATION
from magica_py.solver.constraints.motion import VELOCITY_ATTENUATION as MOTION_ATTENUATION
from magica_py.solver.constraints.tether import VELOCITY_ATTENUATION as TETHER_ATTENUATION
from magica_py.solver.parameters import PRM_RATE_MODE, PRM_RESTORATION_ATTENUATION, step_keep, step_rate, step_share
from magica_py.solver.quality import (
    quality_distance_attenuation, quality_hard_attenuation, quality_restoration_attenuation,
)


@kernel(inline="always")
def restoration_step_attenuation(attenuation, frequency_ratio, rate_mode):
    """D.6's velocity attenuation at the step size outside quality mode: the 90 Hz value in
    MagicaCloth2 mode and at 90 Hz (bit for bit), else ``1 - (1 - attn) 90/f``."""
    if rate_mode == 0 or frequency_ratio == 1.0:
        return attenuation
    return 1.0 - step_share(1.0 - attenuation, frequency_ratio, rate_mode)


@kernel
def step_attenuations(P, b, frequency_ratio):
    """(tether, distance, angle limit, angle restoration, motion) attenuations of a step of block b."""
    mode = int(P[b, PRM_RATE_MODE])
    ratio = frequency_ratio
    tether = quality_hard_attenuation(P, b, ratio, TETHER_ATTENUATION, step_keep(TETHER_ATTENUATION, ratio, mode))
    distance = quality_distance_attenuation(P, b, step_rate(DISTANCE_ATTENUATION, ratio, 1.0, mode))
    limit = quality_hard_attenuation(P, b, ratio, LIMIT_ATTENUATION, step_keep(LIMIT_ATTENUATION, ratio, mode))
    restoration = quality_restoration_attenuation(
        P, b, ratio, restoration_step_attenuation(P[b, PRM_RESTORATION_ATTENUATION], ratio, mode))
    motion = quality_hard_attenuation(P, b, ratio, MOTION_ATTENUATION, step_keep(MOTION_ATTENUATION, ratio, mode))
    return tether, distance, limit, restoration, motion
