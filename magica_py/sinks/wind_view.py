"""Wind as the viewer draws it (magica_py/wind): the zones and the wind each cloth feels.

* Each zone is an entity ``world/wind/<zone>`` with a per-frame ``Transform3D`` (display frame,
  as the colliders) and, in that frame, its area logged once: a sphere (``sphere``, ``radial``)
  as a wireframe ``Ellipsoids3D``, a box as a wireframe ``Boxes3D``; a global zone has none.
* ``world/wind/<zone>/arrows``: ``Arrows3D`` in the zone's frame, per frame: the direction and
  the main speed (``ARROW_M_PER_M_PER_S`` metres of arrow per m/s; a radial zone: six arrows
  out of its centre; a disabled zone: no arrow).
* ``metrics/wind/<cloth>/felt_m_per_s2``: per cloth (team), the length of the mean wind
  acceleration its Move particles felt at the frame's last step (``system.teams.wind_felt``:
  zones and moving wind, after influence, friction and depth weight), a time series.

The frame's data (``WindFrame``) is copied by the recorder from the cloth system's wind field
and team table; the sink buffers it per batch like everything else and sends columns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from magica_py.sinks import layout as L

WIND = "world/wind"
METRIC_WIND = "metrics/wind"
ARROW_M_PER_M_PER_S = 0.1          # m of arrow per m/s of wind
COLOR_ZONE = (120, 200, 255, 255)
COLOR_ARROW = (60, 160, 255, 255)
RADIAL_ARROWS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)


@dataclass
class WindFrame:
    """One frame of wind (scene frame): zones' world position (Z, 3), rotation (Z, 4), main speed
    (Z,) and enabled flag (Z,); every cloth's felt wind acceleration (T, 3)."""

    position: np.ndarray
    rotation: np.ndarray
    main: np.ndarray
    enabled: np.ndarray
    felt: np.ndarray


def wind_frame(system) -> WindFrame | None:
    """The frame's wind of a ``ClothSystem`` (None without wind zones and moving wind)."""
    wind = getattr(system, "wind", None)
    felt = system.teams.wind_felt   # (teams, 3) by team id, gathered from the packed team state
    if wind is None:
        if not (system.parameters.wind_moving_wind > 0.01).any():
            return None
        empty = np.zeros((0, 3))
        return WindFrame(empty, np.zeros((0, 4)), np.zeros(0), np.zeros(0), felt)
    z = wind.table
    return WindFrame(z.world_position, z.world_rotation, z.main, z.enabled.astype(np.float64), felt)


def _mirror_rotation(q: np.ndarray) -> np.ndarray:
    """A rotation seen in the display frame (x mirrored): M R M is (x, -y, -z, w)."""
    return q * np.array([1.0, -1.0, -1.0, 1.0])


class WindView:
    """The drawing of a scene's wind zones and felt winds (``zones``: ``WindZoneSpec``s;
    ``cloths``: the cloth entity names in team order)."""

    def __init__(self, zones, cloths):
        self.zones = list(zones)
        self.cloths = [str(c) for c in cloths]
        self.paths = []
        used = set()
        for zone in self.zones:
            path = f"{WIND}/{L.entity_name(zone.name)}"
            while path in used:
                path += "_"
            used.add(path)
            self.paths.append(path)
        self.felt_paths = []
        for name in self.cloths:
            path = f"{METRIC_WIND}/{L.entity_name(name)}/felt_m_per_s2"
            while path in self.felt_paths:
                path += "_"
            self.felt_paths.append(path)

    def log_statics(self, rr, rec) -> None:
        for zone, path in zip(self.zones, self.paths):
            if zone.mode in ("sphere", "radial"):
                r = zone.radius
                rec.log(path, rr.Ellipsoids3D(half_sizes=[[r, r, r]], fill_mode="majorwireframe",
                                              colors=[COLOR_ZONE]), static=True)
            elif zone.mode == "box":
                rec.log(path, rr.Boxes3D(half_sizes=[[s / 2.0 for s in zone.size]], fill_mode="majorwireframe",
                                         colors=[COLOR_ZONE]), static=True)
            rec.log(path + "/arrows", rr.Arrows3D.from_fields(colors=[COLOR_ARROW]), static=True)
        for path, name in zip(self.felt_paths, self.cloths):
            rec.log(path, rr.SeriesLines(names=[f"{name}: wind felt (m/s²)"], widths=[1.5]), static=True)

    @staticmethod
    def put(buf, row: int, frame: WindFrame) -> None:
        buf.put("wind.position", row, frame.position)
        buf.put("wind.rotation", row, frame.rotation)
        buf.put("wind.main", row, frame.main)
        buf.put("wind.enabled", row, frame.enabled)
        buf.put("wind.felt", row, frame.felt)

    def send(self, rr, rec, index, a: dict, metrics: bool = True) -> None:
        """The batch's columns (``a``: the sink's (n, ...) buffers, scene frame); the felt
        series with ``metrics``."""
        mirror = np.array(L.DISPLAY_MIRROR)
        if "wind.position" in a and len(self.zones):
            n = a["wind.position"].shape[0]
            for i, (zone, path) in enumerate(zip(self.zones, self.paths)):
                translation = a["wind.position"][:, i] * mirror
                quaternion = _mirror_rotation(a["wind.rotation"][:, i])
                rec.send_columns(path, indexes=index, columns=rr.Transform3D.columns(
                    translation=np.ascontiguousarray(translation, np.float32),
                    quaternion=np.ascontiguousarray(quaternion, np.float32)))
                length = a["wind.main"][:, i] * a["wind.enabled"][:, i] * ARROW_M_PER_M_PER_S
                if zone.mode == "radial":   # six arrows pointing out of the centre
                    origins = np.broadcast_to(RADIAL_ARROWS * zone.radius * 0.1, (n,) + RADIAL_ARROWS.shape)
                    vectors = RADIAL_ARROWS[None] * length[:, None, None]
                else:
                    direction = np.asarray(zone.direction, np.float64)
                    vectors = (direction[None, :] * length[:, None])[:, None, :]
                    origins = np.zeros_like(vectors)
                k = vectors.shape[1]
                columns = rr.Arrows3D.columns(
                    origins=np.ascontiguousarray((origins * mirror).reshape(n * k, 3), np.float32),
                    vectors=np.ascontiguousarray((vectors * mirror).reshape(n * k, 3), np.float32)).partition([k] * n)
                rec.send_columns(path + "/arrows", indexes=index, columns=columns)
        if metrics and "wind.felt" in a:
            felt = np.sqrt(np.sum(a["wind.felt"] ** 2, axis=2))
            for t, path in enumerate(self.felt_paths[:felt.shape[1]]):
                rec.send_columns(path, indexes=index, columns=rr.Scalars.columns(scalars=felt[:, t]))
