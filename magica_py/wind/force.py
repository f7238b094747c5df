"""The wind force of one step (docs/solver.md §D.1 "Wind", §C.3 wind time): ``wind_block``.

MagicaCloth2 adds the wind to the force sum of D.1 (``F = gravity + external + wind``,
``F *= scaleRatio``, ``velocity += F dt``, ``nextPos += velocity dt``). Every term of that sum
enters linearly, so ``wind_block`` runs right after ``step.predict_block`` and adds the wind's
share to the Move particles' velocity and prediction: ``velocity += W s dt`` and
``next_pos += W s dt^2`` (W the particle's wind, s the step's scale ratio). It is a separate
stage so that a scene without wind never compiles it; a team that feels no zone and no
moving wind touches no particle (a wind of zero changes no bit of a run).

Per step, first the team part of every lane (``wind_lane``; MagicaCloth2's ``UpdateWind`` in
``SimulationStepTeamUpdate``): each selected zone's phase time advances by ``min((0.2 + 0.5 main/7.5) frequency, 1.5) dt``
and the moving wind takes ``frameMovingSpeed x moving_wind / scaleRatio`` against the
frame's movement direction. Then per Move particle (``WindBatchJob`` / ``WindForceBlend``,
facts from MagicaCloth2's ``SimulationManagerBatch.cs``):

* ``windPos = (teamId + 1) 4.19230645 + rootIndex 0.0023963 (1 - synchronization) 100``:
  one scalar per root line (MagicaCloth2 broadcasts it to xyz, so the ``.xy`` / ``.yx``
  samples below are equal: the wave has one value, used for both angles);
* per zone with ``main >= 0.01``: ``wave = lerp(sin(windPos + 10 time),
  2.3 cnoise(windPos + 2.3132 time), blend)``; turbulence ``k = zone turbulence x
  wind.turbulence``; the direction is turned by ``Euler(wave 45 deg k, wave 45 deg
  lerp(0.1, 0.5, blend) k, 0)`` (Unity's Z-X-Y order) in the frame ``AxisQuaternion(direction)``
  (X then Y Euler angles of the direction), i.e. ``d = Ry(ay) Rx(ax) Ry(by) Rx(bx) (0, 0, 1)``;
  the speed gusts as ``main (1 - unlerp(-1, 1, wave) saturate(1 - main/7.5) k)``;
* the sum (zones, then the moving wind with zone turbulence 1) is scaled by
  ``influence (1 - friction) lerp(1, depth^2, depth_weight)``.

MagicaCloth2's team id starts at 1 for the first cloth; here team t (the lane's team id,
``TI[b, TI_TEAM + l]``) is MagicaCloth2's ``t + 1``. The wind is an acceleration of ``main``
m/s^2 per m/s of wind (no drag law: MagicaCloth2 adds the speed to the force sum like gravity).
"""
from __future__ import annotations

import numpy as np

from magica_py.build.proxy import MOVE
from magica_py.jit import kernel
from magica_py.kernels import portable
from magica_py.kernels.math3d import lerp, saturate, unlerp, v_add, v_scale
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, get4, put1, put3, put4
from magica_py.solver.parameters import (
    PRM_WIND_BLEND, PRM_WIND_DEPTH_WEIGHT, PRM_WIND_FREQUENCY, PRM_WIND_INFLUENCE, PRM_WIND_MOVING_WIND,
    PRM_WIND_SYNCHRONIZATION, PRM_WIND_TURBULENCE,
)
from magica_py.wind.noise import cnoise

WIND_BASE_SPEED = 7.5        # m/s, Define.System.WindBaseSpeed
WIND_MAX_TIME = 10000.0      # Define.System.WindMaxTime: phase wrap (and the start value, negated)
WIND_MIN_MAIN = 0.01         # m/s: weaker zones are skipped
TURBULENCE_ANGLE = 0.7853981633974483   # 45 degrees in radians
TEAM_PHASE = 4.19230645
ROOT_PHASE = 0.0023963


@kernel
def advance_wind_time(time, main, frequency, dt):
    """One step of a zone's phase time (MagicaCloth2's ``UpdateWindTime``)."""
    freq = (0.2 + main / WIND_BASE_SPEED * 0.5) * frequency
    freq = min(freq, 1.5)
    time = time + freq * dt
    if time > WIND_MAX_TIME:
        time -= WIND_MAX_TIME * 2.0
    return time


@kernel
def direction_angles(direction):
    """``AxisToEuler``: the X and Y Euler angles (rad) that turn +Z onto ``direction``, as
    (cos x, sin x, cos y, sin y)."""
    dx, dy, dz = direction
    ay = portable.atan2(dx, dz)
    ax = portable.atan2(-dy, np.sqrt(dx * dx + dz * dz))
    sx, cx = portable.sincos(ax)
    sy, cy = portable.sincos(ay)
    return cx, sx, cy, sy


@kernel
def _rotate_x(c, s, v):
    return v[0], c * v[1] - s * v[2], s * v[1] + c * v[2]


@kernel
def _rotate_y(c, s, v):
    return c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]


@kernel
def zone_wind(main, time, frame, zone_turbulence, turbulence, blend, wind_pos):
    """One zone's wind at a root line (``WindForceBlend``): a vector in m/s. ``frame`` is
    ``direction_angles`` of the zone's direction."""
    if main < WIND_MIN_MAIN:
        return 0.0, 0.0, 0.0
    wave_sin = portable.sin(wind_pos + time * 10.0)
    noise_pos = wind_pos + time * 2.3132
    wave_noise = cnoise(noise_pos, noise_pos) * 2.3
    wave = lerp(wave_sin, wave_noise, blend)
    k = zone_turbulence * turbulence
    angle = wave * TURBULENCE_ANGLE
    bx = angle * k
    by = angle * lerp(0.1, 0.5, blend) * k
    sbx, cbx = portable.sincos(bx)
    sby, cby = portable.sincos(by)
    d = _rotate_y(cby, sby, _rotate_x(cbx, sbx, (0.0, 0.0, 1.0)))
    d = _rotate_y(frame[2], frame[3], _rotate_x(frame[0], frame[1], d))
    gust = unlerp(-1.0, 1.0, wave) * saturate(1.0 - main / WIND_BASE_SPEED) * k
    speed = main - main * gust
    return d[0] * speed, d[1] * speed, d[2] * speed


@kernel(forceinline=False)
def wind_lane(TS, P, b, l, dt):
    """The team part of lane l's wind at this step: zone phases, moving wind, the directions'
    frames (``WIND_ZONE_FRAME``, ``MOVING_WIND_FRAME``). Returns whether the lane's Move
    particles take wind at this step; a lane that feels no zone and no moving wind is not
    touched, and ``WIND_FELT`` restarts at 0 otherwise (it sums the particles' wind)."""
    count = int(get1(TS, b, st.WIND_ZONE_COUNT, l))
    moving_wind = P[b, PRM_WIND_MOVING_WIND]
    if count == 0 and moving_wind <= 0.01:
        return False
    put3(TS, b, st.WIND_FELT, l, (0.0, 0.0, 0.0))
    if P[b, PRM_WIND_INFLUENCE] <= 1e-8:   # WindParams.IsValid
        return False
    frequency = P[b, PRM_WIND_FREQUENCY]
    for s in range(count):
        time = advance_wind_time(get1(TS, b, st.WIND_ZONE_TIME + s * LANES, l),
                                 get1(TS, b, st.WIND_ZONE_MAIN + s * LANES, l), frequency, dt)
        put1(TS, b, st.WIND_ZONE_TIME + s * LANES, l, time)
    moving_main = 0.0
    if moving_wind > 0.01:
        moving_main = get1(TS, b, st.FRAME_MOVING_SPEED, l) * moving_wind / get1(TS, b, st.SCALE_RATIO, l)
        put1(TS, b, st.MOVING_WIND_TIME, l,
             advance_wind_time(get1(TS, b, st.MOVING_WIND_TIME, l), moving_main, frequency, dt))
        d = get3(TS, b, st.FRAME_MOVING_DIRECTION, l)
        put4(TS, b, st.MOVING_WIND_FRAME, l, direction_angles((-d[0], -d[1], -d[2])))
    put1(TS, b, st.MOVING_WIND_MAIN, l, moving_main)
    if count == 0 and moving_main < WIND_MIN_MAIN:
        return False
    for s in range(count):
        put4(TS, b, st.WIND_ZONE_FRAME + 4 * s * LANES, l,
             direction_angles(get3(TS, b, st.WIND_ZONE_DIRECTION + 3 * s * LANES, l)))
    return True


@kernel(forceinline=False)
def line_wind_lane(TS, b, l, wind_pos, turbulence, blend):
    """Lane l's wind at a root line of phase ``wind_pos``: its zones, then its moving wind."""
    wx = 0.0
    wy = 0.0
    wz = 0.0
    for s in range(int(get1(TS, b, st.WIND_ZONE_COUNT, l))):
        cx, cy, cz = zone_wind(get1(TS, b, st.WIND_ZONE_MAIN + s * LANES, l),
                               get1(TS, b, st.WIND_ZONE_TIME + s * LANES, l),
                               get4(TS, b, st.WIND_ZONE_FRAME + 4 * s * LANES, l),
                               get1(TS, b, st.WIND_ZONE_TURBULENCE + s * LANES, l), turbulence, blend, wind_pos)
        wx += cx
        wy += cy
        wz += cz
    moving_main = get1(TS, b, st.MOVING_WIND_MAIN, l)
    if moving_main >= WIND_MIN_MAIN:
        cx, cy, cz = zone_wind(moving_main, get1(TS, b, st.MOVING_WIND_TIME, l), get4(TS, b, st.MOVING_WIND_FRAME, l),
                               1.0, turbulence, blend, wind_pos)
        wx += cx
        wy += cy
        wz += cz
    return wx, wy, wz


@kernel(forceinline=False)
def wind_block(PS, PM, TS, TI, P, BI, topology, b, dt, wind_zones):
    """§D.1 wind of every lane of block b at this step, after ``predict_block`` (module
    docstring). The zones a lane feels are in its ``WIND_ZONE_*`` rows (selected each frame
    by ``selection.select_wind``); ``wind_zones``, the zone table, is not read here.

    The wind depends on a particle only through its root line (windPos): particles of one
    line are mostly consecutive, so each line's wind is computed once per lane (``WIND_LINE``)
    and reused; then the particle loop runs the lanes side by side, a lane without wind
    keeping its values (a select, not an addition of zero: -0.0 stays -0.0)."""
    w = bk.lane_width(BI, b)
    runs = False
    for l in range(w):
        lane_runs = wind_lane(TS, P, b, l, dt)
        put1(TS, b, st.WIND_RUNS, l, 1.0 if lane_runs else 0.0)
        runs = runs or lane_runs
    if not runs:
        return
    g0 = BI[b, bk.BI_G0]
    attribute, root_index = BI[b, bk.BI_ATTRIBUTE], BI[b, bk.BI_ROOT_INDEX]
    influence = P[b, PRM_WIND_INFLUENCE]
    turbulence = P[b, PRM_WIND_TURBULENCE]
    blend = P[b, PRM_WIND_BLEND]
    root_phase = ROOT_PHASE * (1.0 - P[b, PRM_WIND_SYNCHRONIZATION]) * 100.0
    depth_weight = P[b, PRM_WIND_DEPTH_WEIGHT]
    moved = 0
    last_root = -2
    for j in range(BI[b, bk.BI_N]):
        if (topology[attribute + j] & MOVE) == 0:
            continue
        g = g0 + j
        root = topology[root_index + j]
        if root != last_root:
            last_root = root
            line = root if root >= 0 else -1
            for l in range(w):
                if get1(TS, b, st.WIND_RUNS, l) != 0.0:
                    team_phase = (TI[b, bk.TI_TEAM + l] + 2) * TEAM_PHASE      # MagicaCloth2 team id t + 1
                    wind_pos = team_phase + line * root_phase
                    put3(TS, b, st.WIND_LINE, l, line_wind_lane(TS, b, l, wind_pos, turbulence, blend))
        for l in range(w):
            lane_runs = get1(TS, b, st.WIND_RUNS, l) != 0.0
            wx, wy, wz = get3(TS, b, st.WIND_LINE, l)
            depth = get1(PM, g, bk.DEPTH, l)
            k = influence * (1.0 - get1(PS, g, st.FRICTION, l)) * lerp(1.0, depth * depth, depth_weight)
            scale = get1(TS, b, st.SCALE_RATIO, l)
            felt = get3(TS, b, st.WIND_FELT, l)
            summed = (felt[0] + wx * k, felt[1] + wy * k, felt[2] + wz * k)
            dv = (wx * k * scale * dt, wy * k * scale * dt, wz * k * scale * dt)
            velocity = get3(PS, g, st.VELOCITY, l)
            next_pos = get3(PS, g, st.NEXT_POS, l)
            pushed_velocity = v_add(velocity, dv)
            pushed_next_pos = v_add(next_pos, v_scale(dv, dt))
            put3(TS, b, st.WIND_FELT, l, summed if lane_runs else felt)
            put3(PS, g, st.VELOCITY, l, pushed_velocity if lane_runs else velocity)
            put3(PS, g, st.NEXT_POS, l, pushed_next_pos if lane_runs else next_pos)
        moved += 1
    if moved > 0:
        for l in range(w):
            if get1(TS, b, st.WIND_RUNS, l) != 0.0:
                s = get3(TS, b, st.WIND_FELT, l)
                put3(TS, b, st.WIND_FELT, l, (s[0] / moved, s[1] / moved, s[2] / moved))
