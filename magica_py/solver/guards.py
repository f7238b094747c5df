"""Guards (docs/solver.md §E.5): a team whose particles become non-finite or exceed a speed bound
is reset to its base pose, and the reason is recorded in ``TeamState.guard_code`` (the system
turns it into a ``("cloth_reset", {...})`` event). Nothing non-finite reaches a transform."""
from __future__ import annotations

import math


from magica_py.jit import kernel
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.center import snap_lane_to_base_pose
from magica_py.solver.lanes import get1, get3, get4, put1, put3, put4

GUARD_OK = 0
GUARD_NON_FINITE = 1
GUARD_SPEED = 2
GUARD_SPEED_LIMIT = 100.0   # m/s (scaled by the team scale ratio): far above any cloth motion


@kernel(inline="always")
def speed_limit_sq(scale_ratio):
    """Squared speed bound (m/s)^2 of a team with scale ratio ``scale_ratio``."""
    limit = GUARD_SPEED_LIMIT * max(scale_ratio, 1e-6)
    return limit * limit   # a product, not ``** 2``: Python's pow may round otherwise (jit off)


@kernel(inline="always")
def particle_verdict(old_pos, real_velocity, velocity, disp_pos, limit_sq):
    """(non-finite, too fast) of one particle after the steps (branch-free)."""
    finite = True
    s = 0.0
    for c in range(3):
        v = real_velocity[c]
        finite = finite & math.isfinite(old_pos[c]) & math.isfinite(v) & math.isfinite(velocity[c]) \
            & math.isfinite(disp_pos[c])
        s += v * v
    return (not finite), s > limit_sq


@kernel(forceinline=False)
def check_block(PS, TS, BI, b):
    """Every lane's guard verdicts after its steps, side by side: ``GUARD_NON_FINITE`` and
    ``GUARD_TOO_FAST`` (1 when any particle of the lane is non-finite / faster than the bound;
    read by ``guard_code``). One read-only pass, the verdicts OR-ed."""
    g0 = BI[b, bk.BI_G0]
    w = bk.lane_width(BI, b)
    for l in range(w):
        put1(TS, b, st.GUARD_NON_FINITE_SEEN, l, 0.0)
        put1(TS, b, st.GUARD_TOO_FAST_SEEN, l, 0.0)
    for g in range(g0, g0 + BI[b, bk.BI_N]):
        for l in range(w):
            # quality mode: the bound follows the cloth's length unit too (1.0 in faithful mode)
            limit_sq = speed_limit_sq(get1(TS, b, st.SCALE_RATIO, l) * get1(TS, b, st.LENGTH_UNIT, l))
            bad, fast = particle_verdict(get3(PS, g, st.OLD_POS, l), get3(PS, g, st.REAL_VELOCITY, l),
                                         get3(PS, g, st.VELOCITY, l), get3(PS, g, st.DISP_POS, l), limit_sq)
            put1(TS, b, st.GUARD_NON_FINITE_SEEN, l, 1.0 if (bad | (get1(TS, b, st.GUARD_NON_FINITE_SEEN, l) != 0.0))
                 else 0.0)
            put1(TS, b, st.GUARD_TOO_FAST_SEEN, l, 1.0 if (fast | (get1(TS, b, st.GUARD_TOO_FAST_SEEN, l) != 0.0))
                 else 0.0)


@kernel
def lane_guard_code(TS, b, l):
    """The guard code of lane l after ``check_block`` (0 when healthy; non-finite wins)."""
    return guard_code(get1(TS, b, st.GUARD_NON_FINITE_SEEN, l) != 0.0, get1(TS, b, st.GUARD_TOO_FAST_SEEN, l) != 0.0)


@kernel(inline="always")
def guard_code(non_finite, too_fast):
    if non_finite:
        return GUARD_NON_FINITE
    return GUARD_SPEED if too_fast else GUARD_OK


@kernel
def reset_lane_to_base(PS, TS, BI, b, l):
    """Snap lane l's particles to this frame's animated pose with zero velocity (docs/solver.md §C.5 Reset)."""
    g0 = BI[b, bk.BI_G0]
    for g in range(g0, g0 + BI[b, bk.BI_N]):
        snap_lane_to_base_pose(PS, g, l)
        put3(PS, g, st.STEP_BASIC_POS, l, get3(PS, g, st.POSITION, l))
        put4(PS, g, st.STEP_BASIC_ROT, l, get4(PS, g, st.ROTATION, l))
    put1(TS, b, st.VELOCITY_WEIGHT, l, 0.0)
    put1(TS, b, st.BLEND_WEIGHT, l, 0.0)
