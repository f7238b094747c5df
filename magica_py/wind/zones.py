"""Wind zones: the scene's ``wind:`` entries as data, their world pose each frame, and
``WindField``, the per-frame orchestration (events, zone poses, team selection).

A zone is MagicaCloth2's ``MagicaWindZone`` (docs/solver.md §C, §D.1; facts from
``MagicaWindZone.cs`` and ``WindManager.cs``): a mode (global, sphere, box, radial), a pose
(a fixed world pose, or a bone's pose with an optional local offset), a main speed (m/s),
a turbulence, a local direction (directional modes), ``addition`` and ``enabled``, and for
radial zones an attenuation curve over distance / radius. Each frame, before the cloth
kernel, ``WindField.update`` computes every zone's world pose, direction and volume
(``zone_world_poses``) and selects the zones every team feels (``selection.select_wind``).

The zone table is one float64 array ``(zones, ZONE_WIDTH)``, a row per zone, each field at
its columns (``Z_*`` constants; codes and flags exactly as float64): the kernels take that one
array (cheap to pass). ``WindZoneTable`` is the same data for Python, a namedtuple of column
views of the array (``zone_views``), so that writing ``table.main[i]`` writes the array.
Written by ``WindField`` from the specs and events, ``world_*`` and ``volume`` by
``zone_world_poses`` each frame:
"""
from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass, field

import numpy as np

from magica_py.jit import kernel
from magica_py.kernels.math3d import q_mul, q_rotate, v_add, v_mul
from magica_py.params.curves import Curve

GLOBAL, SPHERE, BOX, RADIAL = 0, 1, 2, 10      # MagicaWindZone.Mode values
MODE_CODES = {"global": GLOBAL, "sphere": SPHERE, "box": BOX, "radial": RADIAL}
FLOAT_MAX = 3.4028234663852886e38              # C#'s float.MaxValue: the global zone's volume
EASE_IN_OUT = Curve.hermite(1.0, (1.0, 0.0), (0.0, 0.0))   # AnimationCurve.EaseInOut(0, 1, 1, 0)

# (name, columns, doc)
WIND_ZONE_FIELDS = [
    ("mode", 1, "0 global, 1 sphere, 2 box, 10 radial"),
    ("enabled", 1, "1: blowing (events switch it)"),
    ("addition", 1, "1: additive zone"),
    ("main", 1, "m/s; main speed (events change it)"),
    ("turbulence", 1, "[0,1]"),
    ("size", 3, "m; box edge lengths, or (radius, radius, radius)"),
    ("transform", 1, "hierarchy node the zone follows, or -1"),
    ("local_position", 3, "m; world position, or offset in the bone's space"),
    ("local_rotation", 4, "xyzw; world rotation, or relative to the bone"),
    ("local_direction", 3, "unit; wind direction in the zone's space"),
    ("attenuation", 16, "radial: strength table over distance / radius (§0.3 samples)"),
    ("world_position", 3, "m; this frame (zone_world_poses)"),
    ("world_rotation", 4, "xyzw; this frame"),
    ("world_scale", 3, "the bone's lossy scale, or 1"),
    ("world_direction", 3, "unit; this frame (directional modes)"),
    ("volume", 1, "m^3; FLOAT_MAX for a global zone (the largest: any area zone wins)"),
]
ZONE_COLUMNS: dict[str, tuple[int, int]] = {}
_at = 0
for _name, _size, _doc in WIND_ZONE_FIELDS:
    ZONE_COLUMNS[_name] = (_at, _size)
    __doc__ += f"\n* ``{_name}`` (columns {_at}-{_at + _size - 1}): {_doc}"
    _at += _size
ZONE_WIDTH = _at
del _at, _name, _size, _doc

Z_MODE = ZONE_COLUMNS["mode"][0]
Z_ENABLED = ZONE_COLUMNS["enabled"][0]
Z_ADDITION = ZONE_COLUMNS["addition"][0]
Z_MAIN = ZONE_COLUMNS["main"][0]
Z_TURBULENCE = ZONE_COLUMNS["turbulence"][0]
Z_SIZE = ZONE_COLUMNS["size"][0]
Z_TRANSFORM = ZONE_COLUMNS["transform"][0]
Z_LOCAL_POSITION = ZONE_COLUMNS["local_position"][0]
Z_LOCAL_ROTATION = ZONE_COLUMNS["local_rotation"][0]
Z_LOCAL_DIRECTION = ZONE_COLUMNS["local_direction"][0]
Z_ATTENUATION = ZONE_COLUMNS["attenuation"][0]
Z_WORLD_POSITION = ZONE_COLUMNS["world_position"][0]
Z_WORLD_ROTATION = ZONE_COLUMNS["world_rotation"][0]
Z_WORLD_SCALE = ZONE_COLUMNS["world_scale"][0]
Z_WORLD_DIRECTION = ZONE_COLUMNS["world_direction"][0]
Z_VOLUME = ZONE_COLUMNS["volume"][0]

WindZoneTable = namedtuple("WindZoneTable", [name for name, _size, _doc in WIND_ZONE_FIELDS])


def zone_views(zones: np.ndarray) -> WindZoneTable:
    """The fields of the packed zone table as column views, (Z,) or (Z, k) (they share its memory)."""
    views = {}
    for name, (first, size) in ZONE_COLUMNS.items():
        views[name] = zones[:, first] if size == 1 else zones[:, first:first + size]
    return WindZoneTable(**views)


@kernel
def row3(a, i, col):
    """Columns col .. col+2 of row i."""
    return a[i, col], a[i, col + 1], a[i, col + 2]


@kernel
def row4(a, i, col):
    return a[i, col], a[i, col + 1], a[i, col + 2], a[i, col + 3]


@kernel
def put_row3(a, i, col, v):
    a[i, col] = v[0]
    a[i, col + 1] = v[1]
    a[i, col + 2] = v[2]


@kernel
def put_row4(a, i, col, q):
    a[i, col] = q[0]
    a[i, col + 1] = q[1]
    a[i, col + 2] = q[2]
    a[i, col + 3] = q[3]


@dataclass(frozen=True)
class WindZoneSpec:
    """One checked ``wind:`` entry (``transform`` a hierarchy index or -1)."""

    name: str
    mode: str = "global"
    main: float = 5.0
    turbulence: float = 1.0
    direction: tuple = (0.0, 0.0, 1.0)
    radius: float = 10.0
    size: tuple = (10.0, 10.0, 10.0)
    addition: bool = False
    enabled: bool = True
    transform: int = -1
    position: tuple = (0.0, 0.0, 0.0)
    rotation: tuple = (0.0, 0.0, 0.0, 1.0)
    attenuation: Curve = field(default=EASE_IN_OUT)
    document_path: str = ""

    @staticmethod
    def from_resolved(z: dict, hierarchy) -> "WindZoneSpec":
        from magica_py.config.errors import format_path

        return WindZoneSpec(
            name=z["name"], mode=z["mode"], main=z["main"], turbulence=z["turbulence"],
            direction=tuple(z["direction"]), radius=z["radius"], size=tuple(z["size"]),
            addition=z["addition"], enabled=z["enabled"],
            transform=-1 if z["transform"] is None else int(hierarchy.index(z["transform"])),
            position=tuple(z["position"]), rotation=tuple(z["rotation"]), attenuation=z["attenuation"],
            document_path=format_path(z["path"]))


def zone_table(specs) -> np.ndarray:
    """The packed zone table of ``specs`` (world fields filled by the first ``zone_world_poses``)."""
    zones = np.zeros((len(specs), ZONE_WIDTH))
    z = zone_views(zones)
    for i, spec in enumerate(specs):
        z.mode[i] = MODE_CODES[spec.mode]
        z.enabled[i] = 1 if spec.enabled else 0
        z.addition[i] = 1 if spec.addition else 0
        z.main[i] = spec.main
        z.turbulence[i] = spec.turbulence
        z.size[i] = (spec.radius,) * 3 if spec.mode in ("sphere", "radial") else spec.size
        z.transform[i] = spec.transform
        z.local_position[i] = spec.position
        z.local_rotation[i] = spec.rotation
        z.local_direction[i] = spec.direction
        z.attenuation[i] = spec.attenuation.samples
    return zones


@kernel
def zone_world_poses(Z, world_position, world_rotation, lossy_scale):
    """Every zone's world pose, direction and volume this frame (``WindManager.AlwaysWindUpdate``);
    ``Z``: the packed zone table."""
    for i in range(Z.shape[0]):
        pos = row3(Z, i, Z_LOCAL_POSITION)
        rot = row4(Z, i, Z_LOCAL_ROTATION)
        scale = (1.0, 1.0, 1.0)
        bone = int(Z[i, Z_TRANSFORM])
        if bone >= 0:
            bone_rot = row4(world_rotation, bone, 0)
            scale = row3(lossy_scale, bone, 0)
            pos = v_add(row3(world_position, bone, 0), q_rotate(bone_rot, v_mul(pos, scale)))
            rot = q_mul(bone_rot, rot)
        put_row3(Z, i, Z_WORLD_POSITION, pos)
        put_row4(Z, i, Z_WORLD_ROTATION, rot)
        put_row3(Z, i, Z_WORLD_SCALE, scale)
        put_row3(Z, i, Z_WORLD_DIRECTION, q_rotate(rot, row3(Z, i, Z_LOCAL_DIRECTION)))
        mode = Z[i, Z_MODE]
        if mode == BOX:
            Z[i, Z_VOLUME] = (Z[i, Z_SIZE] * scale[0] * Z[i, Z_SIZE + 1] * scale[1] * Z[i, Z_SIZE + 2]
                              * scale[2])
        elif mode == SPHERE or mode == RADIAL:
            r = Z[i, Z_SIZE] * scale[0]
            Z[i, Z_VOLUME] = (4.0 / 3.0) * r * r * r * math.pi
        else:
            Z[i, Z_VOLUME] = FLOAT_MAX


class WindField:
    """The scene's wind zones at run time: events, world poses, the per-frame team selection.

    ``update(tables, hierarchy)`` runs once per frame before the cloth kernel
    (``ClothSystem.select_wind``); ``apply_event({zone, enabled, main})`` is the ``wind`` scene
    event; ``set_zone(name, ...)`` the same from Python. ``zones`` is the packed table (what
    ``kernel_table`` hands to the frame kernel), ``table`` its column views."""

    def __init__(self, specs):
        self.specs = tuple(specs)
        self.names = [s.name for s in self.specs]
        self.zones = zone_table(self.specs)
        self.table = zone_views(self.zones)

    def __len__(self) -> int:
        return len(self.specs)

    def index(self, name) -> int:
        if isinstance(name, (int, np.integer)) and not isinstance(name, bool):
            if not 0 <= int(name) < len(self.names):
                raise KeyError(f"wind zone index {name} out of range [0, {len(self.names)})")
            return int(name)
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no wind zone named {name!r}; zones: {', '.join(self.names) or 'none'}") from None

    def set_zone(self, name, enabled: bool | None = None, main: float | None = None) -> None:
        """Switch a zone on or off and / or set its main speed (m/s, [0, 30]) from the next frame."""
        i = self.index(name)
        if main is not None:
            main = float(main)
            if not (math.isfinite(main) and 0.0 <= main <= 30.0):
                raise ValueError(f"wind zone {self.names[i]!r}: main must be in [0, 30] m/s, got {main}")
            self.table.main[i] = main
        if enabled is not None:
            self.table.enabled[i] = 1 if enabled else 0

    def apply_event(self, payload: dict) -> None:
        self.set_zone(payload["zone"], payload.get("enabled"), payload.get("main"))

    def kernel_table(self) -> np.ndarray:
        """The zone table as the frame kernel takes it (``wind_zones``): the packed array."""
        return self.zones

    def update(self, tables, hierarchy) -> None:
        """Zone world poses, then the zones every team feels (``selection.update_wind``, one
        numba call); ``tables``: the solver's ``frame.Tables``, ``hierarchy``: its
        ``frame.HierarchyArrays``."""
        from magica_py.wind.selection import update_wind

        update_wind(self.zones, tables.TS, tables.TI, tables.P, tables.BI, tables.PT, tables.topology,
                    tables.blocks, hierarchy.world_position, hierarchy.world_rotation, hierarchy.lossy_scale)

    def capture_state(self) -> dict:
        return {"enabled": self.table.enabled.copy(), "main": self.table.main.copy()}

    def restore_state(self, state: dict) -> None:
        self.table.enabled[:] = state["enabled"]
        self.table.main[:] = state["main"]
