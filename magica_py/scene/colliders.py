"""Colliders: the scene's ``ColliderSet`` (model data, read-only) and their world shapes.

``ColliderSet`` is a structure-of-arrays over n colliders (docs/solver.md §G.1), built once from the
validated ``colliders`` section; every array is ``writeable=False``:

==================  ===========  =====  ===================================================
field               shape        units  meaning
==================  ===========  =====  ===================================================
names               list[str]    -      collider names (YAML order)
shape               (n,) int8    -      0 sphere, 1 capsule, 2 plane (``SPHERE`` ...)
transform           (n,) int32   index  hierarchy node the collider is attached to
center              (n, 3)       m      local offset in the transform's space
radius              (n,)         m      sphere radius / capsule start radius (0 for planes)
end_radius          (n,)         m      capsule end radius (= radius unless separated)
length              (n,)         m      capsule length tip to tip (0 otherwise)
direction           (n,) int8    -      capsule axis: 0 X, 1 Y, 2 Z
reverse_direction   (n,) bool    -      capsule axis negated
aligned_on_center   (n,) bool    -      capsule centred on the transform (else it starts there)
==================  ===========  =====  ===================================================

Construction from the YAML entries (already validated by the config package)::

    ColliderSet.from_specs(colliders: list[dict], hierarchy, static_transforms=None)

Each entry: ``name``; ``transform`` (a bone name, or an int hierarchy index) or, for a
static collider, no transform; ``center`` (default 0); exactly one of ``sphere: {radius}``,
``capsule: {radius, end_radius=radius, length, direction=x|y|z|0|1|2 (default y),
reverse=false, aligned_on_center=true}``, ``plane: {}``. A collider without a transform
sits on a static node the config package creates before the hierarchy is built:
``static_transform_bone(entry)`` gives that ``BoneSpec`` (named
``static_transform_name(name)``, placed at the entry's ``position`` and ``rotation`` |
``euler``); ``from_specs`` finds it by that name, or takes the index from
``static_transforms[collider name]`` when given.

``world_shapes(hierarchy)`` evaluates every collider at the hierarchy's current world pose
(§G.2 frame pose, §G.3 shape work data) with numpy: it is what the Rerun sink draws and
the oracle the solver's collider kernels are tested against.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.kernels import portable

SPHERE, CAPSULE, PLANE = 0, 1, 2
SHAPE_NAMES = ("sphere", "capsule", "plane")
AXIS_NAMES = {"x": 0, "y": 1, "z": 2}
SCALE_EPSILON = 1e-6  # §G.2: |S| below this is clamped and the collider suspended


def static_transform_name(collider_name: str) -> str:
    """Name of the static node carrying a collider that has no ``transform``."""
    return f"collider:{collider_name}"


def static_transform_bone(entry: dict) -> BoneSpec:
    """The root ``BoneSpec`` for a collider without ``transform``: ``position``,
    ``rotation`` (xyzw) or ``euler`` (degrees, Unity Z-X-Y order), ``scale``."""
    from magica_py.scene.rigs import rotation_from_spec

    return BoneSpec(name=static_transform_name(entry["name"]), parent=None,
                    position=tuple(float(c) for c in entry.get("position", (0.0, 0.0, 0.0))),
                    rotation=rotation_from_spec(entry),
                    scale=tuple(float(c) for c in entry.get("scale", (1.0, 1.0, 1.0))),
                    tags={"collider": entry["name"]})


def _axis_index(value, where: str) -> int:
    if isinstance(value, str) and value.lower() in AXIS_NAMES:
        return AXIS_NAMES[value.lower()]
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool) and 0 <= value <= 2:
        return int(value)
    raise ValueError(f"{where}.direction: expected x, y or z, got {value!r}")


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class ColliderSet:
    """Collider model data (see the module docstring for the fields)."""

    names: tuple[str, ...]
    shape: np.ndarray
    transform: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    end_radius: np.ndarray
    length: np.ndarray
    direction: np.ndarray
    reverse_direction: np.ndarray
    aligned_on_center: np.ndarray

    @property
    def count(self) -> int:
        return len(self.names)

    def __len__(self) -> int:
        return self.count

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no collider named {name!r}") from None

    @staticmethod
    def empty() -> "ColliderSet":
        return ColliderSet.from_specs([], None)

    @staticmethod
    def from_specs(colliders: list[dict], hierarchy: TransformHierarchy | None,
                   static_transforms: dict[str, int] | None = None) -> "ColliderSet":
        n = len(colliders)
        shape = np.zeros(n, np.int8)
        transform = np.zeros(n, np.int32)
        center = np.zeros((n, 3))
        radius = np.zeros(n)
        end_radius = np.zeros(n)
        length = np.zeros(n)
        direction = np.ones(n, np.int8)
        reverse = np.zeros(n, bool)
        aligned = np.ones(n, bool)
        static_transforms = static_transforms or {}
        for i, c in enumerate(colliders):
            where = f"colliders[{i}]"
            name = c["name"]
            kinds = [k for k in SHAPE_NAMES if k in c]
            if len(kinds) != 1:
                raise ValueError(f"{where}: expected exactly one of sphere, capsule, plane, got {kinds}")
            kind = kinds[0]
            body = c[kind] or {}
            shape[i] = SHAPE_NAMES.index(kind)
            t = c.get("transform")
            if t is None:
                t = static_transforms.get(name, static_transform_name(name))
            if isinstance(t, str):
                try:
                    t = hierarchy.index(t)
                except KeyError:
                    raise ValueError(f"{where}.transform: no transform named {t!r}") from None
            transform[i] = int(t)
            center[i] = c.get("center", (0.0, 0.0, 0.0))
            if kind == "sphere":
                radius[i] = end_radius[i] = float(body["radius"])
            elif kind == "capsule":
                radius[i] = float(body["radius"])
                end_radius[i] = float(body.get("end_radius", body["radius"]))
                length[i] = float(body["length"])
                direction[i] = _axis_index(body.get("direction", "y"), f"{where}.capsule")
                reverse[i] = bool(body.get("reverse", body.get("reverse_direction", False)))
                aligned[i] = bool(body.get("aligned_on_center", True))
            for field_name, values in (("radius", radius), ("end_radius", end_radius), ("length", length)):
                if not np.isfinite(values[i]) or values[i] < 0.0:
                    raise ValueError(f"{where}.{kind}.{field_name}: expected a number >= 0, got {values[i]}")
        return ColliderSet(tuple(c["name"] for c in colliders), *(
            _frozen(a) for a in (shape, transform, center, radius, end_radius, length,
                                 direction, reverse, aligned)))

    def subset(self, indices) -> "ColliderSet":
        """The colliders at ``indices`` (in that order), e.g. the ones a cloth lists."""
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        return ColliderSet(tuple(self.names[i] for i in idx), *(
            _frozen(np.array(a[idx])) for a in (
                self.shape, self.transform, self.center, self.radius, self.end_radius,
                self.length, self.direction, self.reverse_direction, self.aligned_on_center)))

    def world_shapes(self, hierarchy: TransformHierarchy) -> "ColliderWorldShapes":
        return world_shapes(self, hierarchy)


@dataclass
class ColliderWorldShapes:
    """Every collider at the current world pose (n rows, the ``ColliderSet`` order).

    ``position`` (n,3) frame position ``P + (R (center * sign S)) * |S|`` (§G.2);
    ``rotation`` (n,4) world rotation R; ``scale`` (n,3) lossy scale S with tiny
    components clamped to 1e-6; ``suspended`` (n,) bool: some |S| < 1e-6 (§G.2 ScaleSuspend,
    the solver skips the collider that frame). ``start``/``end`` (n,3) centres of the two end
    spheres (capsule, §G.3 step 5; both = ``position`` for spheres and planes);
    ``radius``/``end_radius`` (n,) scaled radii (sphere: radius |S.x|; capsule: radii |S.axis|;
    plane 0); ``normal`` (n,3) plane normal ``R (0, sign S.y, 0)`` (zero for other shapes);
    ``axis`` (n,3) the capsule's world axis from end to start (unit; zero otherwise).
    """

    shape: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    scale: np.ndarray
    suspended: np.ndarray
    start: np.ndarray
    end: np.ndarray
    radius: np.ndarray
    end_radius: np.ndarray
    normal: np.ndarray
    axis: np.ndarray


def _rotation_matrices(q: np.ndarray) -> np.ndarray:
    """(n,3,3) rotation matrices of unit quaternions q (n,4, xyzw)."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    m = np.empty((q.shape[0], 3, 3))
    m[:, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    m[:, 0, 1] = 2.0 * (x * y - z * w)
    m[:, 0, 2] = 2.0 * (x * z + y * w)
    m[:, 1, 0] = 2.0 * (x * y + z * w)
    m[:, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    m[:, 1, 2] = 2.0 * (y * z - x * w)
    m[:, 2, 0] = 2.0 * (x * z - y * w)
    m[:, 2, 1] = 2.0 * (y * z + x * w)
    m[:, 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return m


def world_shapes(colliders: ColliderSet, hierarchy: TransformHierarchy) -> ColliderWorldShapes:
    """Evaluate ``colliders`` at ``hierarchy``'s world pose (§G.2, §G.3); numpy, no kernel."""
    t = colliders.transform
    n = colliders.count
    pos = hierarchy.world_position[t]
    rot = hierarchy.world_rotation[t]
    scale = hierarchy.lossy_scale[t].copy()
    tiny = np.abs(scale) < SCALE_EPSILON
    suspended = tiny.any(axis=1)
    scale[tiny] = SCALE_EPSILON
    sign = np.where(scale < 0.0, -1.0, 1.0)
    rmat = _rotation_matrices(rot)
    frame_pos = pos + portable.rotate_vectors(rmat, colliders.center * sign) * np.abs(scale)

    shape = colliders.shape
    radius = np.zeros(n)
    end_radius = np.zeros(n)
    start = frame_pos.copy()
    end = frame_pos.copy()
    normal = np.zeros((n, 3))
    axis_world = np.zeros((n, 3))

    sphere = shape == SPHERE
    radius[sphere] = colliders.radius[sphere] * np.abs(scale[sphere, 0])
    end_radius[sphere] = radius[sphere]

    cap = np.flatnonzero(shape == CAPSULE)
    if cap.size:
        d = colliders.direction[cap].astype(np.int64)
        s = scale[cap, d]                              # signed scale on the capsule axis
        axis = np.zeros((cap.size, 3))
        axis[np.arange(cap.size), d] = np.where(s < 0.0, -1.0, 1.0)
        axis[colliders.reverse_direction[cap]] *= -1.0
        k = np.abs(s)
        rs = colliders.radius[cap] * k
        re = colliders.end_radius[cap] * k
        length = colliders.length[cap] * k
        aligned = colliders.aligned_on_center[cap]
        a = np.where(aligned, 0.5 * length, 0.0)
        b = np.where(aligned, 0.5 * length, length - rs)
        a = np.maximum(a - rs, 0.0)
        b = np.maximum(b - re, 0.0)
        world_axis = portable.rotate_vectors(rmat[cap], axis)
        start[cap] = frame_pos[cap] + world_axis * a[:, None]
        end[cap] = frame_pos[cap] - world_axis * b[:, None]
        radius[cap] = rs
        end_radius[cap] = re
        axis_world[cap] = world_axis

    plane = np.flatnonzero(shape == PLANE)
    if plane.size:
        normal[plane] = rmat[plane, :, 1] * sign[plane, 1][:, None]  # R (0, sign S.y, 0)

    return ColliderWorldShapes(shape=shape.copy(), position=frame_pos, rotation=rot.copy(),
                               scale=scale, suspended=suspended, start=start, end=end,
                               radius=radius, end_radius=end_radius, normal=normal,
                               axis=axis_world)
