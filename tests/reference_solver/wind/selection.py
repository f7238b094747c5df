"""Per frame: the wind zones each team feels (docs/solver.md §C; MagicaCloth2's
``TeamManager`` ``Wind()`` in the center/inertia job, facts from its public source).

For every live team, at its center (the mean world position of its fixed particles' bones,
as C.2; the component's position when it has none), zones are visited in scene order:

* disabled zones are skipped; so is an additive zone once three were taken;
* the center must lie inside the area: a box in the zone's local space (``|local| 2 <= size``),
  a sphere (``|local| <= radius``); a global zone has no area;
* a non-additive zone must not be larger (volume) than the area zone taken so far: the
  smallest containing area zone wins (the global zone, of volume float.MaxValue, is the
  fallback, and a later zone of equal volume replaces an earlier one);
* a radial zone blows from its centre towards the team, its main speed scaled by its
  attenuation curve at distance / radius (none at the very centre);
* a zone whose main speed is below 0.01 m/s is skipped.

A taken zone keeps the phase time it had last frame when it was felt then, else starts at
-10000 (MagicaCloth2's ``-WindMaxTime``). A team whose ``wind.influence`` is <= 1e-8 feels no
zone. Writes the ``wind_zone_*`` fields of the team table.
"""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, q_inverse, q_rotate, saturate, v_length, v_sub
from magica_py.params.curves import evaluate_curve_clamp01
from reference_solver.wind.force import WIND_MAX_TIME, WIND_MIN_MAIN
from reference_solver.wind.zones import BOX, FLOAT_MAX, RADIAL, SPHERE, zone_world_poses

MAX_ADDITIONS = 3
SLOTS = 4


@kernel
def team_center(m, world_position, team):
    """C.2's center position from this frame's bone poses."""
    n = m.team_center_count[team]
    if n == 0:
        return load3(world_position, m.team_component_transform[team])
    start = m.team_center_start[team]
    x = 0.0
    y = 0.0
    z = 0.0
    for i in range(start, start + n):
        node = m.transform_index[m.center_fixed[i]]
        x += world_position[node, 0]
        y += world_position[node, 1]
        z += world_position[node, 2]
    return x / n, y / n, z / n


@kernel
def _write_slot(ts, team, slot, zone, time, main, direction, turbulence):
    ts.wind_zone_id[team, slot] = zone
    ts.wind_zone_time[team, slot] = time
    ts.wind_zone_main[team, slot] = main
    ts.wind_zone_direction[team, slot, 0] = direction[0]
    ts.wind_zone_direction[team, slot, 1] = direction[1]
    ts.wind_zone_direction[team, slot, 2] = direction[2]
    ts.wind_zone_turbulence[team, slot] = turbulence


@kernel
def _remove_slot(ts, team, zone, count):
    """``RemoveAtSwapBack`` of the slot of ``zone`` (if any); the new count."""
    for s in range(count):
        if ts.wind_zone_id[team, s] == zone:
            last = count - 1
            d = (ts.wind_zone_direction[team, last, 0], ts.wind_zone_direction[team, last, 1],
                 ts.wind_zone_direction[team, last, 2])
            _write_slot(ts, team, s, ts.wind_zone_id[team, last], ts.wind_zone_time[team, last],
                        ts.wind_zone_main[team, last], d, ts.wind_zone_turbulence[team, last])
            ts.wind_zone_id[team, last] = -1
            return last
    return count


@kernel
def select_team_wind(z, m, prm, ts, world_position, team):
    """The zones team ``team`` feels this frame (module docstring)."""
    old_count = ts.wind_zone_count[team]
    old_id = (ts.wind_zone_id[team, 0], ts.wind_zone_id[team, 1], ts.wind_zone_id[team, 2],
              ts.wind_zone_id[team, 3])
    old_time = (ts.wind_zone_time[team, 0], ts.wind_zone_time[team, 1], ts.wind_zone_time[team, 2],
                ts.wind_zone_time[team, 3])
    for s in range(SLOTS):
        ts.wind_zone_id[team, s] = -1
    count = 0
    if prm.wind_influence[team] > 1e-8:
        center = team_center(m, world_position, team)
        min_volume = FLOAT_MAX
        additions = 0
        latest = -1
        for i in range(z.mode.shape[0]):
            if z.enabled[i] == 0:
                continue
            addition = z.addition[i] != 0
            if addition and additions >= MAX_ADDITIONS:
                continue
            mode = z.mode[i]
            pos = load3(z.world_position, i)
            scale = load3(z.world_scale, i)
            rel = q_rotate(q_inverse(load4(z.world_rotation, i)), v_sub(center, pos))
            local = (rel[0] / scale[0], rel[1] / scale[1], rel[2] / scale[2])
            distance = v_length(local)
            if mode == BOX:
                if (abs(local[0]) * 2.0 > z.size[i, 0] or abs(local[1]) * 2.0 > z.size[i, 1]
                        or abs(local[2]) * 2.0 > z.size[i, 2]):
                    continue
            elif mode == SPHERE or mode == RADIAL:
                if distance > z.size[i, 0]:
                    continue
            if not addition and z.volume[i] > min_volume:
                continue
            direction = load3(z.world_direction, i)
            main = z.main[i]
            if mode == RADIAL:
                if distance <= 1e-6:
                    continue
                away = v_sub(center, pos)
                length = v_length(away)
                direction = (away[0] / length, away[1] / length, away[2] / length)
                main *= evaluate_curve_clamp01(z.attenuation[i], saturate(distance / z.size[i, 0]))
            if main < WIND_MIN_MAIN:
                continue
            time = -WIND_MAX_TIME
            for s in range(old_count):
                if old_id[s] == i:
                    time = old_time[s]
            if addition:
                additions += 1
            else:
                if latest >= 0:
                    count = _remove_slot(ts, team, latest, count)
                min_volume = z.volume[i]
                latest = i
            if count < SLOTS:
                _write_slot(ts, team, count, i, time, main, direction, z.turbulence[i])
                count += 1
    ts.wind_zone_count[team] = count
    if count == 0 and prm.wind_moving_wind[team] <= 0.01:
        ts.wind_felt[team, 0] = 0.0
        ts.wind_felt[team, 1] = 0.0
        ts.wind_felt[team, 2] = 0.0


@kernel
def select_wind(z, m, prm, ts, world_position):
    """``select_team_wind`` for every live team."""
    for i in range(m.live_teams.shape[0]):
        select_team_wind(z, m, prm, ts, world_position, m.live_teams[i])


@kernel
def update_wind(z, tables):
    """The per-frame wind: zone world poses, then every live team's zones (``tables``: the
    solver's ``SolverTables``)."""
    h = tables.hierarchy
    zone_world_poses(z, h.world_position, h.world_rotation, h.lossy_scale)
    select_wind(z, tables.model, tables.parameters, tables.teams, h.world_position)
