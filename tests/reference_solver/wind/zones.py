"""Wind zones: the scene's ``wind:`` entries as data, their world pose each frame, and
``WindField``, the per-frame orchestration (events, zone poses, team selection).

A zone is MagicaCloth2's ``MagicaWindZone`` (docs/solver.md §C, §D.1; facts from
``MagicaWindZone.cs`` and ``WindManager.cs``): a mode (global, sphere, box, radial), a pose
(a fixed world pose, or a bone's pose with an optional local offset), a main speed (m/s),
a turbulence, a local direction (directional modes), ``addition`` and ``enabled``, and for
radial zones an attenuation curve over distance / radius. Each frame, before the cloth
kernel, ``WindField.update`` computes every zone's world pose, direction and volume
(``zone_world_poses``) and selects the zones every team feels (``selection.select_wind``).

``WindZoneTable`` (one row per zone; written by ``WindField`` from the specs and events,
``world_*`` and ``volume`` by ``zone_world_poses`` each frame):
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import config, types
from numba.experimental import structref

from magica_py.jit import kernel
from magica_py.kernels.math3d import load3, load4, q_mul, q_rotate, store3, store4, v_add, v_mul
from magica_py.params.curves import Curve
from reference_solver.solver.fields import F64, I32, U8, allocate, make_soa

GLOBAL, SPHERE, BOX, RADIAL = 0, 1, 2, 10      # MagicaWindZone.Mode values
MODE_CODES = {"global": GLOBAL, "sphere": SPHERE, "box": BOX, "radial": RADIAL}
FLOAT_MAX = 3.4028234663852886e38              # C#'s float.MaxValue: the global zone's volume
EASE_IN_OUT = Curve.hermite(1.0, (1.0, 0.0), (0.0, 0.0))   # AnimationCurve.EaseInOut(0, 1, 1, 0)

WIND_ZONE_FIELDS = [
    ("mode", "zone", (), I32, "0 global, 1 sphere, 2 box, 10 radial"),
    ("enabled", "zone", (), U8, "1: blowing (events switch it)"),
    ("addition", "zone", (), U8, "1: additive zone"),
    ("main", "zone", (), F64, "m/s; main speed (events change it)"),
    ("turbulence", "zone", (), F64, "[0,1]"),
    ("size", "zone", (3,), F64, "m; box edge lengths, or (radius, radius, radius)"),
    ("transform", "zone", (), I32, "hierarchy node the zone follows, or -1"),
    ("local_position", "zone", (3,), F64, "m; world position, or offset in the bone's space"),
    ("local_rotation", "zone", (4,), F64, "xyzw; world rotation, or relative to the bone"),
    ("local_direction", "zone", (3,), F64, "unit; wind direction in the zone's space"),
    ("attenuation", "zone", (16,), F64, "radial: strength table over distance / radius (§0.3 samples)"),
    ("world_position", "zone", (3,), F64, "m; this frame (zone_world_poses)"),
    ("world_rotation", "zone", (4,), F64, "xyzw; this frame"),
    ("world_scale", "zone", (3,), F64, "the bone's lossy scale, or 1"),
    ("world_direction", "zone", (3,), F64, "unit; this frame (directional modes)"),
    ("volume", "zone", (), F64, "m^3; FLOAT_MAX for a global zone (the largest: any area zone wins)"),
]
WindZoneTable = make_soa("WindZoneTable", WIND_ZONE_FIELDS)
__doc__ += WindZoneTable.__doc__


# the zone table as the kernels take it: a StructRef sharing the arrays (one pointer to type
# per call instead of 16 arrays; the same pattern as ``solver/tables.py``)
@structref.register
class WindZoneTableType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class WindZones(structref.StructRefProxy):
    """``WindZoneTable`` for the kernels."""


structref.define_proxy(WindZones, WindZoneTableType, list(WindZoneTable._fields))


@kernel
def new_wind_zones(*fields):
    return WindZones(*fields)


def zone_kernel_table(table: WindZoneTable):
    """The zone table as the kernels take it (the namedtuple itself with the JIT off)."""
    return table if config.DISABLE_JIT else new_wind_zones(*table)


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


def zone_table(specs) -> WindZoneTable:
    """The zone table of ``specs`` (world fields filled by the first ``zone_world_poses``)."""
    z = allocate(WindZoneTable, {"zone": len(specs)})
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
    return z


@kernel
def zone_world_poses(z, world_position, world_rotation, lossy_scale):
    """Every zone's world pose, direction and volume this frame (``WindManager.AlwaysWindUpdate``)."""
    for i in range(z.mode.shape[0]):
        pos = load3(z.local_position, i)
        rot = load4(z.local_rotation, i)
        scale = (1.0, 1.0, 1.0)
        bone = z.transform[i]
        if bone >= 0:
            bone_rot = load4(world_rotation, bone)
            scale = load3(lossy_scale, bone)
            pos = v_add(load3(world_position, bone), q_rotate(bone_rot, v_mul(pos, scale)))
            rot = q_mul(bone_rot, rot)
        store3(z.world_position, i, pos)
        store4(z.world_rotation, i, rot)
        store3(z.world_scale, i, scale)
        store3(z.world_direction, i, q_rotate(rot, load3(z.local_direction, i)))
        mode = z.mode[i]
        if mode == 2:
            z.volume[i] = z.size[i, 0] * scale[0] * z.size[i, 1] * scale[1] * z.size[i, 2] * scale[2]
        elif mode == 1 or mode == 10:
            r = z.size[i, 0] * scale[0]
            z.volume[i] = (4.0 / 3.0) * r * r * r * math.pi
        else:
            z.volume[i] = FLOAT_MAX


class WindField:
    """The scene's wind zones at run time: events, world poses, the per-frame team selection.

    ``update(system)`` runs once per frame before the cloth kernel (``ClothSystem.step_frame``);
    ``apply_event({zone, enabled, main})`` is the ``wind`` scene event; ``set_zone(name, ...)``
    the same from Python."""

    def __init__(self, specs):
        self.specs = tuple(specs)
        self.names = [s.name for s in self.specs]
        self.table = zone_table(self.specs)
        self._struct = None        # the table as a kernel StructRef (shares its arrays)

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

    def update(self, solver_tables) -> None:
        """Zone world poses, then every live team's zone selection (``selection.update_wind``,
        one numba call; ``solver_tables``: the frame kernel's ``solver.tables.SolverTables``)."""
        from reference_solver.wind.selection import update_wind

        if self._struct is None:
            self._struct = zone_kernel_table(self.table)
        update_wind(self._struct, solver_tables)

    def capture_state(self) -> dict:
        return {"enabled": self.table.enabled.copy(), "main": self.table.main.copy()}

    def restore_state(self, state: dict) -> None:
        self.table.enabled[:] = state["enabled"]
        self.table.main[:] = state["main"]
