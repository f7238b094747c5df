"""The wind force of one step (docs/solver.md §D.1 "Wind", §C.3 wind time): ``wind_team``.

MagicaCloth2 adds the wind to the force sum of D.1 (``F = gravity + external + wind``,
``F *= scaleRatio``, ``velocity += F dt``, ``nextPos += velocity dt``). Every term of that sum
enters linearly, so ``wind_team`` runs right after ``step.predict_team`` and adds the wind's
share to the Move particles' velocity and prediction: ``velocity += W s dt`` and
``next_pos += W s dt^2`` (W the particle's wind, s the step's scale ratio). It is a separate
stage so that a scene without wind never compiles it; a team that feels no zone and no
moving wind returns before touching a particle (a wind of zero changes no bit of a run).

Per step, first the team part (MagicaCloth2's ``UpdateWind`` in ``SimulationStepTeamUpdate``):
each selected zone's phase time advances by ``min((0.2 + 0.5 main/7.5) frequency, 1.5) dt``
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

MagicaCloth2's team id starts at 1 for the first cloth; here team t is MagicaCloth2's
``t + 1``. The wind is an acceleration of ``main`` m/s^2 per m/s of wind (no drag law:
MagicaCloth2 adds the speed to the force sum like gravity).
"""
from __future__ import annotations

import math

from magica_py.jit import kernel
from magica_py.kernels import portable
from magica_py.kernels.math3d import lerp, load3, saturate, store3, unlerp
from reference_solver.wind.noise import cnoise

MOVE = 0x02
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
    ax = portable.atan2(-dy, math.sqrt(dx * dx + dz * dz))
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


@kernel
def wind_team(m, ps, prm, ts, team, dt):
    """§D.1 wind of team ``team`` at this step, after ``predict_team`` (module docstring)."""
    # the tables' arrays used in loops, read once (a table field read takes and releases a reference)
    m_attribute, m_depth, m_root_index = m.attribute, m.depth, m.root_index
    m_team_particle_count, ps_friction, ps_next_pos = m.team_particle_count, ps.friction, ps.next_pos
    ps_velocity, ts_moving_wind_time, ts_wind_zone_main = ps.velocity, ts.moving_wind_time, ts.wind_zone_main
    ts_wind_zone_time, ts_wind_zone_turbulence = ts.wind_zone_time, ts.wind_zone_turbulence
    influence = prm.wind_influence[team]
    ts.wind_felt[team, 0] = 0.0
    ts.wind_felt[team, 1] = 0.0
    ts.wind_felt[team, 2] = 0.0
    if influence <= 1e-8:   # WindParams.IsValid
        return
    frequency = prm.wind_frequency[team]
    count = ts.wind_zone_count[team]
    for s in range(count):
        ts_wind_zone_time[team, s] = advance_wind_time(ts_wind_zone_time[team, s], ts_wind_zone_main[team, s],
                                                       frequency, dt)
    moving_main = 0.0
    moving_frame = (1.0, 0.0, 1.0, 0.0)
    if prm.wind_moving_wind[team] > 0.01:
        moving_main = ts.frame_moving_speed[team] * prm.wind_moving_wind[team] / ts.scale_ratio[team]
        ts_moving_wind_time[team] = advance_wind_time(ts_moving_wind_time[team], moving_main, frequency, dt)
        d = load3(ts.frame_moving_direction, team)
        moving_frame = direction_angles((-d[0], -d[1], -d[2]))
    ts.moving_wind_main[team] = moving_main
    if count == 0 and moving_main < WIND_MIN_MAIN:
        return
    f0 = (1.0, 0.0, 1.0, 0.0)
    f1 = f0
    f2 = f0
    f3 = f0
    if count > 0:
        f0 = direction_angles(load3(ts.wind_zone_direction[team], 0))
    if count > 1:
        f1 = direction_angles(load3(ts.wind_zone_direction[team], 1))
    if count > 2:
        f2 = direction_angles(load3(ts.wind_zone_direction[team], 2))
    if count > 3:
        f3 = direction_angles(load3(ts.wind_zone_direction[team], 3))
    turbulence = prm.wind_turbulence[team]
    blend = prm.wind_blend[team]
    root_phase = ROOT_PHASE * (1.0 - prm.wind_synchronization[team]) * 100.0
    team_phase = (team + 2) * TEAM_PHASE      # MagicaCloth2 team id t + 1
    depth_weight = prm.wind_depth_weight[team]
    scale = ts.scale_ratio[team]
    start = m.team_particle_start[team]
    sx = 0.0
    sy = 0.0
    sz = 0.0
    moved = 0
    # the wind depends on the particle only through its root line (windPos): particles of one
    # line are mostly consecutive, so the line's wind is computed once and reused
    last_root = -2
    wx = 0.0
    wy = 0.0
    wz = 0.0
    for p in range(start, start + m_team_particle_count[team]):
        if (m_attribute[p] & MOVE) == 0:
            continue
        root = m_root_index[p]
        if root != last_root:
            last_root = root
            wind_pos = team_phase + (root - start if root >= 0 else -1) * root_phase
            wx = 0.0
            wy = 0.0
            wz = 0.0
            for s in range(count):
                frame = f0 if s == 0 else (f1 if s == 1 else (f2 if s == 2 else f3))
                cx, cy, cz = zone_wind(ts_wind_zone_main[team, s], ts_wind_zone_time[team, s], frame,
                                       ts_wind_zone_turbulence[team, s], turbulence, blend, wind_pos)
                wx += cx
                wy += cy
                wz += cz
            if moving_main >= WIND_MIN_MAIN:
                cx, cy, cz = zone_wind(moving_main, ts_moving_wind_time[team], moving_frame, 1.0, turbulence, blend,
                                       wind_pos)
                wx += cx
                wy += cy
                wz += cz
        depth = m_depth[p]
        k = influence * (1.0 - ps_friction[p]) * lerp(1.0, depth * depth, depth_weight)
        ax = wx * k * scale
        ay = wy * k * scale
        az = wz * k * scale
        sx += wx * k
        sy += wy * k
        sz += wz * k
        moved += 1
        dvx = ax * dt
        dvy = ay * dt
        dvz = az * dt
        ps_velocity[p, 0] += dvx
        ps_velocity[p, 1] += dvy
        ps_velocity[p, 2] += dvz
        ps_next_pos[p, 0] += dvx * dt
        ps_next_pos[p, 1] += dvy * dt
        ps_next_pos[p, 2] += dvz * dt
    if moved > 0:
        store3(ts.wind_felt, team, (sx / moved, sy / moved, sz / moved))
