"""The velocity attenuations of one step's constraints (docs/solver.md §D.3-§D.9), read by the
step (``frame.run_step``).

Each is the 90 Hz value converted to the step size by the team's rate mode
(``parameters.step_rate``), then by quality mode where it applies (``quality.py``).
"""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.solver.constraints.angle import LIMIT_ATTENUATION
from magica_py.solver.constraints.distance import VELOCITY_ATTENUATION as DISTANCE_ATTENUATION
from magica_py.solver.constraints.motion import VELOCITY_ATTENUATION as MOTION_ATTENUATION
from magica_py.solver.constraints.tether import VELOCITY_ATTENUATION as TETHER_ATTENUATION
from magica_py.solver.parameters import step_rate
from magica_py.solver.quality import (
    quality_distance_attenuation, quality_hard_attenuation, quality_restoration_attenuation,
)


@kernel
def step_attenuations(prm, team, frequency_ratio):
    """(tether, distance, angle limit, angle restoration, motion) attenuations of a step."""
    mode = prm.rate_mode[team]
    ratio = frequency_ratio
    tether = quality_hard_attenuation(prm, team, ratio, TETHER_ATTENUATION,
                                      step_rate(TETHER_ATTENUATION, ratio, 1.0, mode))
    distance = quality_distance_attenuation(prm, team, step_rate(DISTANCE_ATTENUATION, ratio, 1.0, mode))
    limit = quality_hard_attenuation(prm, team, ratio, LIMIT_ATTENUATION, step_rate(LIMIT_ATTENUATION, ratio, 1.0, mode))
    restoration = quality_restoration_attenuation(
        prm, team, ratio, step_rate(prm.restoration_attenuation[team], ratio, 1.0, mode))
    motion = quality_hard_attenuation(prm, team, ratio, MOTION_ATTENUATION,
                                      step_rate(MOTION_ATTENUATION, ratio, 1.0, mode))
    return tether, distance, limit, restoration, motion
