"""Rig generators for secondary-motion bones (chain, fan, skirt, sheet), rig placement and crowds.

Every generator returns ``list[BoneSpec]`` (``magica_py.scene.hierarchy``) in parents-before-
children order, ready to be appended to a rig's explicit bones. All lengths are metres, all
angles degrees, all vectors are given in the *parent bone's* local space.

Bone axis convention (what the solver sees, docs/solver.md §B.2: normal = bone +Y, tangent = bone +Z)
------------------------------------------------------------------------------------------
* local **+Y** points along the strand, from a bone to its child (like Mixamo / Unity
  humanoid bones), so ``child.local_position == (0, segment, 0)``;
* local **+Z** is the bend direction: "outward" for fans and skirts, and for chains the
  parent's +Y made orthogonal to the chain (a horizontal tail curls upward), or the parent's
  -Z when the chain is (nearly) vertical (a hanging strand curls backward); for sheets the
  side the sheet faces (``across x direction``);
* local **+X** = Y x Z is the curl axis. ``curl`` degrees per bone rotate each bone about its
  own +X relative to the previous one, bending the strand towards its +Z (a negative curl
  bends the other way). The first segment always follows ``direction`` exactly.

So every bone has a well-defined orthonormal frame; no frame is degenerate.

Lengths: a strand of ``bones`` bones has ``bones - 1`` equal segments between bone origins
and ``length`` is their sum (the distance covered by the particles, tip bone included).

Naming (the cloths refer to roots with globs such as ``skirt_*_0``)
-------------------------------------------------------------------
* chain: ``<name>_<bone>`` (``tail_0`` .. ``tail_7``), bone 0 is the root;
* fan, skirt and sheet: ``<name>_<strand>_<bone>`` (``skirt_3_0`` is the root of strand 3); each
  strand root is a child of ``parent`` and the strand's other bones are its descendants;
* instances: ``<bone>#<i>`` for every bone of instance ``i`` (0-based, instance 0 included),
  see ``instance_name``; the same rule maps glob patterns (``skirt_*_0#3``).

Generated bones carry ``tags = {"generator": kind, "part": name, "strand": s, "bone": k}``.

Entry points (keyword arguments are the YAML keys of ``rigs[].parts[]``, already validated)
------------------------------------------------------------------------------------------
* ``chain(name, parent, bones, length, direction=(0,-1,0), curl=0, position=(0,0,0),
  curl_axis=None)``
* ``fan(name, parent, strands, bones, length, spread=120, tilt=30, radius=0.08,
  axis=(0,-1,0), facing=(0,0,-1), curl=0, position=(0,0,0))``
* ``skirt(name, parent, strands=12, bones=4, radius=0.15, length=0.4, flare=20,
  axis=(0,-1,0), facing=(0,0,1), curl=0, position=(0,0,0))``
* ``sheet(name, parent, strands, bones, length, width, direction=(0,-1,0), across=(1,0,0),
  curl=0, position=(0,0,0))``: parallel strands (capes, flags), named like fans;
* ``part_bones(part)`` for one ``{"chain": {...}}`` / ``{"fan": {...}}`` / ``{"skirt": {...}}``
  entry;
* ``rig_bones(rig)`` for a whole ``rigs[]`` entry (explicit bones, parts, placement,
  instances) -> ``list[BoneSpec]``;
* ``instance_rig(bones, count, spacing, columns, row_spacing=None)``, ``instance_offsets``,
  ``instance_name(name, i)``.
"""
from __future__ import annotations

import math

import numpy as np

from magica_py.kernels.math3d import (
    q_axis_angle,
    q_from_euler_degrees,
    q_look_rotation,
    q_mul,
    q_normalize,
    q_rotate,
)
from magica_py.scene.hierarchy import BoneSpec
from magica_py.kernels import portable

UP = (0.0, 1.0, 0.0)
BACK = (0.0, 0.0, -1.0)


# ----------------------------------------------------------------------------- small vector helpers
def _unit(v, what: str) -> tuple[float, float, float]:
    a = np.asarray(v, dtype=np.float64)
    n = portable.norm(a)
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"{what}: expected a non-zero vector, got {list(v)}")
    return tuple(float(x) for x in a / n)


def _orthogonal_part(v, axis) -> np.ndarray:
    """v without its component along the unit vector axis."""
    v = np.asarray(v, dtype=np.float64)
    a = np.asarray(axis, dtype=np.float64)
    return v - portable.dot3(v, a) * a


def bone_frame(y_axis, z_hint) -> tuple[float, float, float, float]:
    """Rotation whose +Y is ``y_axis`` (unit) and whose +Z is ``z_hint`` made orthogonal to it.

    Falls back to the parent's -Z (then +X) when the hint is parallel to ``y_axis``.
    """
    for hint in (z_hint, BACK, (1.0, 0.0, 0.0)):
        z = _orthogonal_part(hint, y_axis)
        n = portable.norm(z)
        if n > 1e-6:
            z = tuple(float(c) for c in z / n)
            return tuple(q_look_rotation(z, tuple(y_axis)))
    raise AssertionError("unreachable: three independent hints")


def _strand(prefix: str, parent: str, bones: int, length: float, root_position,
            root_rotation, curl: float, tags: dict) -> list[BoneSpec]:
    """One strand: a root at root_position/root_rotation, then bones along local +Y."""
    if bones < 1:
        raise ValueError(f"{prefix}: expected bones >= 1, got {bones}")
    if length < 0.0:
        raise ValueError(f"{prefix}: expected length >= 0, got {length}")
    segment = length / (bones - 1) if bones > 1 else 0.0
    curl_rotation = tuple(q_axis_angle((1.0, 0.0, 0.0), math.radians(curl)))
    out = [BoneSpec(name=f"{prefix}_0", parent=parent,
                    position=tuple(float(c) for c in root_position),
                    rotation=tuple(float(c) for c in root_rotation),
                    tags=dict(tags, bone=0))]
    for k in range(1, bones):
        out.append(BoneSpec(name=f"{prefix}_{k}", parent=f"{prefix}_{k - 1}",
                            position=(0.0, segment, 0.0), rotation=curl_rotation,
                            tags=dict(tags, bone=k)))
    return out


# ----------------------------------------------------------------------------- generators
def chain(name: str, parent: str | None, bones: int, length: float,
          direction=(0.0, -1.0, 0.0), curl: float = 0.0, position=(0.0, 0.0, 0.0),
          curl_axis=None) -> list[BoneSpec]:
    """A single strand (tail, ribbon, hair strand, antenna): ``<name>_0 .. <name>_{bones-1}``.

    ``position``: parent-relative position of the first bone. ``direction``: the first
    segment's direction in the parent's space. ``curl``: degrees per bone about the bone's
    +X axis (see the module docstring); ``curl_axis`` (parent space) overrides that axis.
    """
    d = _unit(direction, f"chain {name!r} direction")
    if curl_axis is None:
        z_hint = UP if abs(d[1]) < 0.99 else BACK
        rotation = bone_frame(d, z_hint)
    else:
        x = _orthogonal_part(_unit(curl_axis, f"chain {name!r} curl_axis"), d)
        if portable.norm(x) < 1e-6:
            raise ValueError(f"chain {name!r}: curl_axis must not be parallel to direction")
        rotation = bone_frame(d, np.cross(x, d))  # Z = X x Y
    return _strand(name, parent, bones, length, position, rotation, curl,
                   {"generator": "chain", "part": name, "strand": 0})


def _ring_strands(kind: str, name: str, parent: str | None, strands: int, bones: int,
                  length: float, azimuths_deg, tilt: float, radius: float, axis, facing,
                  curl: float, position) -> list[BoneSpec]:
    """Strands rooted on a ring of ``radius`` around ``axis``; strand s at azimuths_deg[s].

    Outward direction at azimuth phi: ``facing`` (made orthogonal to the axis) rotated by phi
    about the axis. Strand direction: the axis tilted by ``tilt`` towards the outward
    direction. Root frame: +Y = strand direction, +Z = outward tilted the same way (so the
    frame stays orthonormal even at tilt = 90).
    """
    a = np.asarray(_unit(axis, f"{kind} {name!r} axis"))
    c = _orthogonal_part(_unit(facing, f"{kind} {name!r} facing"), a)
    if portable.norm(c) < 1e-6:
        raise ValueError(f"{kind} {name!r}: facing must not be parallel to the axis")
    c = tuple(c / portable.norm(c))
    if radius < 0.0:
        raise ValueError(f"{kind} {name!r}: expected radius >= 0, got {radius}")
    t = math.radians(tilt)
    base = np.asarray(position, dtype=np.float64)
    out: list[BoneSpec] = []
    for s, phi in enumerate(azimuths_deg):
        outward = np.asarray(q_rotate(tuple(q_axis_angle(tuple(a), math.radians(phi))), c))
        sin_t, cos_t = portable.sincos(t)
        y = cos_t * a + sin_t * outward
        z = cos_t * outward - sin_t * a
        rotation = bone_frame(tuple(y / portable.norm(y)), tuple(z))
        root = base + radius * outward
        tags = {"generator": kind, "part": name, "strand": s, "azimuth": float(phi)}
        out.extend(_strand(f"{name}_{s}", parent, bones, length, root, rotation, curl, tags))
    return out


def fan(name: str, parent: str | None, strands: int, bones: int, length: float,
        spread: float = 120.0, tilt: float = 30.0, radius: float = 0.08,
        axis=(0.0, -1.0, 0.0), facing=(0.0, 0.0, -1.0), curl: float = 0.0,
        position=(0.0, 0.0, 0.0)) -> list[BoneSpec]:
    """A hair bundle: ``strands`` chains spread over ``spread`` degrees around ``axis``.

    Strand s sits at azimuth ``-spread/2 + s * spread/(strands-1)`` (0 for a single strand)
    measured about ``axis`` from ``facing`` (default: hanging down, centred on the back
    of the head, -Z). Its root is ``radius`` from ``position`` and it points along the axis
    tilted outward by ``tilt`` degrees. A spread of 360 spaces the strands evenly around the
    full circle without duplicating the seam.
    """
    if strands < 1:
        raise ValueError(f"fan {name!r}: expected strands >= 1, got {strands}")
    if spread >= 360.0:
        azimuths = [s * 360.0 / strands for s in range(strands)]
    elif strands == 1:
        azimuths = [0.0]
    else:
        azimuths = [-0.5 * spread + s * spread / (strands - 1) for s in range(strands)]
    return _ring_strands("fan", name, parent, strands, bones, length, azimuths, tilt, radius,
                         axis, facing, curl, position)


def skirt(name: str, parent: str | None, strands: int = 12, bones: int = 4,
          radius: float = 0.15, length: float = 0.4, flare: float = 20.0,
          axis=(0.0, -1.0, 0.0), facing=(0.0, 0.0, 1.0), curl: float = 0.0,
          position=(0.0, 0.0, 0.0)) -> list[BoneSpec]:
    """N strands of M bones evenly around a ring, hanging along ``axis`` flared by ``flare``.

    Strand s sits at azimuth ``s * 360 / strands`` about ``axis`` from ``facing`` (strand 0
    at the front, +Z). Neighbouring strands are adjacent in index order and strand
    ``strands-1`` closes the loop to strand 0 (what ``sequential_loop_mesh`` expects).
    """
    if strands < 1:
        raise ValueError(f"skirt {name!r}: expected strands >= 1, got {strands}")
    azimuths = [s * 360.0 / strands for s in range(strands)]
    return _ring_strands("skirt", name, parent, strands, bones, length, azimuths, flare,
                         radius, axis, facing, curl, position)


def sheet(name: str, parent: str | None, strands: int, bones: int, length: float,
          width: float, direction=(0.0, -1.0, 0.0), across=(1.0, 0.0, 0.0), curl: float = 0.0,
          position=(0.0, 0.0, 0.0)) -> list[BoneSpec]:
    """Parallel strands side by side (cape, flag, wide ribbon; ``sequential_non_loop_mesh``).

    Strand roots are evenly spaced over ``width`` along ``across``, centred on ``position``
    (strand 0 at ``-across * width/2``); every strand runs along ``direction``. Bone +Z is
    ``across x direction`` (for a cape hanging down the back, across +X: +Z points back,
    away from the body), so a positive ``curl`` bends the strands that way.
    """
    if strands < 1:
        raise ValueError(f"sheet {name!r}: expected strands >= 1, got {strands}")
    if width < 0.0:
        raise ValueError(f"sheet {name!r}: expected width >= 0, got {width}")
    d = np.asarray(_unit(direction, f"sheet {name!r} direction"))
    a = _orthogonal_part(_unit(across, f"sheet {name!r} across"), d)
    if portable.norm(a) < 1e-6:
        raise ValueError(f"sheet {name!r}: across must not be parallel to direction")
    a /= portable.norm(a)
    rotation = bone_frame(tuple(d), tuple(np.cross(a, d)))
    base = np.asarray(position, dtype=np.float64)
    out: list[BoneSpec] = []
    for s in range(strands):
        u = s / (strands - 1) - 0.5 if strands > 1 else 0.0
        tags = {"generator": "sheet", "part": name, "strand": s}
        out.extend(_strand(f"{name}_{s}", parent, bones, length, base + u * width * a,
                           rotation, curl, tags))
    return out


GENERATORS = {"chain": chain, "fan": fan, "skirt": skirt, "sheet": sheet}


def part_bones(part: dict) -> list[BoneSpec]:
    """Bones of one ``parts[]`` entry: a single-key mapping ``{kind: keyword arguments}``."""
    if len(part) != 1:
        raise ValueError(f"a rig part has exactly one of {sorted(GENERATORS)}, got {sorted(part)}")
    (kind, args), = part.items()
    if kind not in GENERATORS:
        raise ValueError(f"unknown rig part {kind!r}; expected one of {sorted(GENERATORS)}")
    return GENERATORS[kind](**args)


# ----------------------------------------------------------------------------- rigs and crowds
def rotation_from_spec(spec: dict, default=(0.0, 0.0, 0.0, 1.0)) -> tuple[float, float, float, float]:
    """``rotation`` (quaternion xyzw) or ``euler`` (degrees, Unity order Z, X, Y) of a mapping."""
    if spec.get("rotation") is not None:
        q = np.asarray(spec["rotation"], dtype=np.float64)
        n = portable.norm(q)
        if n < 1e-12:
            raise ValueError(f"zero-length quaternion {list(spec['rotation'])}")
        return tuple(float(c) for c in q / n)
    if spec.get("euler") is not None:
        x, y, z = (float(c) for c in spec["euler"])
        return tuple(q_from_euler_degrees(x, y, z))
    return tuple(default)


def explicit_bone(spec: dict) -> BoneSpec:
    """A ``bones[]`` entry: name, parent (None = rig root), position, rotation|euler, scale."""
    return BoneSpec(name=spec["name"], parent=spec.get("parent"),
                    position=tuple(float(c) for c in spec.get("position", (0.0, 0.0, 0.0))),
                    rotation=rotation_from_spec(spec),
                    scale=tuple(float(c) for c in spec.get("scale", (1.0, 1.0, 1.0))),
                    tags=dict(spec.get("tags", {})))


def place_roots(bones: list[BoneSpec], position=(0.0, 0.0, 0.0),
                rotation=(0.0, 0.0, 0.0, 1.0)) -> list[BoneSpec]:
    """Compose the rig placement (position, rotation) onto every root (parent None) in place."""
    q = tuple(float(c) for c in rotation)
    p = np.asarray(position, dtype=np.float64)
    for b in bones:
        if b.parent is None:
            b.position = tuple(float(c) for c in p + np.asarray(q_rotate(q, tuple(map(float, b.position)))))
            b.rotation = tuple(q_normalize(q_mul(q, tuple(map(float, b.rotation)))))
    return bones


def instance_name(name: str, i: int) -> str:
    """Name of rig bone (or glob pattern) ``name`` in instance ``i``: ``<name>#<i>``."""
    return f"{name}#{i}"


def default_row_spacing(spacing) -> np.ndarray:
    """Row step when none is given: ``spacing`` turned 90 degrees about +Y in the ground plane,
    same length: spacing (1.5, 0, 0) -> rows (0, 0, 1.5); (0, 0, 2) -> (-2, 0, 0); a purely
    vertical spacing -> rows along +X."""
    s = np.asarray(spacing, dtype=np.float64)
    row = np.array([-s[2], 0.0, s[0]])  # s rotated -90 deg about Y, horizontal part only
    n = portable.norm(row)
    length = portable.norm(s)
    if n < 1e-12:
        return np.array([length, 0.0, 0.0])
    return row / n * length


def instance_offsets(count: int, spacing, columns: int | None = None, row_spacing=None) -> np.ndarray:
    """(count, 3) offsets: instance i in column ``i % columns`` and row ``i // columns``.

    ``offset_i = column * spacing + row * row_spacing``; ``columns`` None means one row;
    ``row_spacing`` defaults to ``default_row_spacing(spacing)``.
    """
    if count < 1:
        raise ValueError(f"instances.count: expected >= 1, got {count}")
    columns = count if not columns else int(columns)
    if columns < 1:
        raise ValueError(f"instances.columns: expected >= 1, got {columns}")
    s = np.asarray(spacing, dtype=np.float64)
    r = default_row_spacing(s) if row_spacing is None else np.asarray(row_spacing, dtype=np.float64)
    i = np.arange(count)
    return (i % columns)[:, None] * s[None, :] + (i // columns)[:, None] * r[None, :]


def instance_rig(bones: list[BoneSpec], count: int, spacing, columns: int | None = None,
                 row_spacing=None) -> list[BoneSpec]:
    """``count`` copies of a rig: names ``<bone>#<i>``, roots shifted by ``instance_offsets``.

    The offset is added to each root's local position (roots have no parent, so it is a
    world offset). A parent outside ``bones`` keeps its name (every instance hangs under it,
    unshifted). Bones come out instance by instance, each in the input order; tags gain
    ``instance``.
    """
    offsets = instance_offsets(count, spacing, columns, row_spacing)
    own = {b.name for b in bones}
    out: list[BoneSpec] = []
    for i in range(count):
        for b in bones:
            position = tuple(map(float, b.position))
            if b.parent is None:
                position = tuple(float(c) for c in np.asarray(position) + offsets[i])
            out.append(BoneSpec(name=instance_name(b.name, i),
                                parent=instance_name(b.parent, i) if b.parent in own else b.parent,
                                position=position, rotation=tuple(b.rotation),
                                scale=tuple(b.scale), tags=dict(b.tags, instance=i)))
    return out


def rig_bones(rig: dict) -> list[BoneSpec]:
    """All bones of one validated ``rigs[]`` entry.

    Order: explicit ``bones`` (``explicit_bone``), then each ``parts`` entry
    (``part_bones``); then the rig placement (``position``, ``rotation`` | ``euler``) is
    composed onto the roots; then ``instances`` ({count, spacing, columns, row_spacing})
    replicates everything (``instance_rig``). Parents that are not bones of this rig keep
    their name, so a rig may hang under a bone of an earlier rig (not when instanced).
    """
    bones = [explicit_bone(b) for b in rig.get("bones", ())]
    for part in rig.get("parts", ()):
        bones.extend(part_bones(part))
    place_roots(bones, rig.get("position", (0.0, 0.0, 0.0)), rotation_from_spec(rig))
    inst = rig.get("instances")
    if inst:
        bones = instance_rig(bones, int(inst["count"]), inst.get("spacing", (1.0, 0.0, 0.0)),
                             inst.get("columns"), inst.get("row_spacing"))
    return bones
