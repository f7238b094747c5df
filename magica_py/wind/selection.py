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
zone. Writes the ``WIND_ZONE_*`` rows of the team table (``state.TEAM``), lane by lane.
"""
from __future__ import annotations

from magica_py.jit import kernel
from magica_py.kernels.math3d import q_inverse, q_rotate, saturate, v_length, v_sub
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES, get1, get3, put1, put3
from magica_py.solver.parameters import PRM_WIND_INFLUENCE, PRM_WIND_MOVING_WIND, curve_at_clamp01
from magica_py.wind.force import WIND_MAX_TIME, WIND_MIN_MAIN
from magica_py.wind.zones import (
    BOX, FLOAT_MAX, RADIAL, SPHERE, Z_ADDITION, Z_ATTENUATION, Z_ENABLED, Z_MAIN, Z_MODE, Z_SIZE, Z_TURBULENCE,
    Z_VOLUME, Z_WORLD_DIRECTION, Z_WORLD_POSITION, Z_WORLD_ROTATION, Z_WORLD_SCALE, row3, row4, zone_world_poses,
)

MAX_ADDITIONS = 3
SLOTS = st.WIND_SLOTS


@kernel(forceinline=False)
def team_center_lane(TI, BI, PT, topology, b, l, world_position):
    """C.2's center position of lane l's team from this frame's bone poses."""
    n = BI[b, bk.BI_CENTERS]
    if n == 0:
        return row3(world_position, TI[b, bk.TI_COMPONENT + l], 0)
    g0 = BI[b, bk.BI_G0]
    at = BI[b, bk.BI_CENTER_FIXED]
    x = 0.0
    y = 0.0
    z = 0.0
    for i in range(n):
        node = PT[g0 + topology[at + i], l]
        x += world_position[node, 0]
        y += world_position[node, 1]
        z += world_position[node, 2]
    return x / n, y / n, z / n


@kernel
def _write_slot(TS, b, l, slot, zone, time, main, direction, turbulence):
    put1(TS, b, st.WIND_ZONE_ID + slot * LANES, l, zone)
    put1(TS, b, st.WIND_ZONE_TIME + slot * LANES, l, time)
    put1(TS, b, st.WIND_ZONE_MAIN + slot * LANES, l, main)
    put3(TS, b, st.WIND_ZONE_DIRECTION + 3 * slot * LANES, l, direction)
    put1(TS, b, st.WIND_ZONE_TURBULENCE + slot * LANES, l, turbulence)


@kernel
def _remove_slot(TS, b, l, zone, count):
    """``RemoveAtSwapBack`` of the slot of ``zone`` (if any); the new count."""
    for s in range(count):
        if get1(TS, b, st.WIND_ZONE_ID + s * LANES, l) == zone:
            last = count - 1
            _write_slot(TS, b, l, s, get1(TS, b, st.WIND_ZONE_ID + last * LANES, l),
                        get1(TS, b, st.WIND_ZONE_TIME + last * LANES, l),
                        get1(TS, b, st.WIND_ZONE_MAIN + last * LANES, l),
                        get3(TS, b, st.WIND_ZONE_DIRECTION + 3 * last * LANES, l),
                        get1(TS, b, st.WIND_ZONE_TURBULENCE + last * LANES, l))
            put1(TS, b, st.WIND_ZONE_ID + last * LANES, l, -1.0)
            return last
    return count


@kernel(forceinline=False)
def select_team_wind(Z, TS, TI, P, BI, PT, topology, b, l, world_position):
    """The zones lane l's team of block b feels this frame (module docstring); ``Z``: the
    packed zone table (``zones.zone_table``)."""
    old_count = int(get1(TS, b, st.WIND_ZONE_COUNT, l))
    old_id = (get1(TS, b, st.WIND_ZONE_ID, l), get1(TS, b, st.WIND_ZONE_ID + LANES, l),
              get1(TS, b, st.WIND_ZONE_ID + 2 * LANES, l), get1(TS, b, st.WIND_ZONE_ID + 3 * LANES, l))
    old_time = (get1(TS, b, st.WIND_ZONE_TIME, l), get1(TS, b, st.WIND_ZONE_TIME + LANES, l),
                get1(TS, b, st.WIND_ZONE_TIME + 2 * LANES, l), get1(TS, b, st.WIND_ZONE_TIME + 3 * LANES, l))
    for s in range(SLOTS):
        put1(TS, b, st.WIND_ZONE_ID + s * LANES, l, -1.0)
    count = 0
    if P[b, PRM_WIND_INFLUENCE] > 1e-8:
        center = team_center_lane(TI, BI, PT, topology, b, l, world_position)
        min_volume = FLOAT_MAX
        additions = 0
        latest = -1
        for i in range(Z.shape[0]):
            if Z[i, Z_ENABLED] == 0.0:
                continue
            addition = Z[i, Z_ADDITION] != 0.0
            if addition and additions >= MAX_ADDITIONS:
                continue
            mode = Z[i, Z_MODE]
            pos = row3(Z, i, Z_WORLD_POSITION)
            scale = row3(Z, i, Z_WORLD_SCALE)
            rel = q_rotate(q_inverse(row4(Z, i, Z_WORLD_ROTATION)), v_sub(center, pos))
            local = (rel[0] / scale[0], rel[1] / scale[1], rel[2] / scale[2])
            distance = v_length(local)
            if mode == BOX:
                if (abs(local[0]) * 2.0 > Z[i, Z_SIZE] or abs(local[1]) * 2.0 > Z[i, Z_SIZE + 1]
                        or abs(local[2]) * 2.0 > Z[i, Z_SIZE + 2]):
                    continue
            elif mode == SPHERE or mode == RADIAL:
                if distance > Z[i, Z_SIZE]:
                    continue
            if not addition and Z[i, Z_VOLUME] > min_volume:
                continue
            direction = row3(Z, i, Z_WORLD_DIRECTION)
            main = Z[i, Z_MAIN]
            if mode == RADIAL:
                if distance <= 1e-6:
                    continue
                away = v_sub(center, pos)
                length = v_length(away)
                direction = (away[0] / length, away[1] / length, away[2] / length)
                main *= curve_at_clamp01(Z, i, Z_ATTENUATION, saturate(distance / Z[i, Z_SIZE]))
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
                    count = _remove_slot(TS, b, l, latest, count)
                min_volume = Z[i, Z_VOLUME]
                latest = i
            if count < SLOTS:
                _write_slot(TS, b, l, count, float(i), time, main, direction, Z[i, Z_TURBULENCE])
                count += 1
    put1(TS, b, st.WIND_ZONE_COUNT, l, float(count))
    if count == 0 and P[b, PRM_WIND_MOVING_WIND] <= 0.01:
        put3(TS, b, st.WIND_FELT, l, (0.0, 0.0, 0.0))


@kernel
def select_wind(Z, TS, TI, P, BI, PT, topology, blocks, world_position):
    """``select_team_wind`` for every team of the live blocks (free lanes are skipped)."""
    for k in range(blocks.shape[0]):
        b = blocks[k]
        for l in range(bk.lane_width(BI, b)):
            if TI[b, bk.TI_TEAM + l] >= 0:
                select_team_wind(Z, TS, TI, P, BI, PT, topology, b, l, world_position)


@kernel(forceinline=False)
def update_wind(Z, TS, TI, P, BI, PT, topology, blocks, world_position, world_rotation, lossy_scale):
    """The per-frame wind: zone world poses, then every team's zones (the solver's arrays:
    ``frame.Tables`` and ``frame.HierarchyArrays``)."""
    zone_world_poses(Z, world_position, world_rotation, lossy_scale)
    select_wind(Z, TS, TI, P, BI, PT, topology, blocks, world_position)
