"""VRM avatars: the glTF rig plus spring-bone chains and colliders as BoneCloth descriptions.

Supported: VRM 0.x (``extensions.VRM``: ``humanoid``, ``secondaryAnimation`` bone groups
and sphere collider groups) and VRM 1.0 (``VRMC_vrm`` humanoid, ``VRMC_springBone``
springs / joints / sphere and capsule colliders, ``VRMC_springBone_extended_collider``
plane; its ``inside`` shapes have no MagicaCloth2 counterpart and are skipped with a note).

Conventions (see docs/import.md):

* Coordinates: VRM 0.x is mirrored along Z, VRM 1.0 along X (``coords``). VRM 0.x
  collider offsets and gravity directions are stored in Unity's own axes by UniVRM and are
  used as they are; VRM 1.0 offsets, tails, normals and gravity are glTF axes and converted.
* Chains: a VRM 0.x bone group lists root bones whose whole subtrees swing; a VRM 1.0
  spring lists its joints, the last one being the tail (its parameters are unused). Either
  way the root becomes a MagicaCloth root bone (Fixed; its rotation follows its child via
  ``root_rotation`` = 1) and the descendants become Move particles. VRM 1.0 descendants of
  the root that are not joints are marked ``invalid``.
* Tail convention: UniVRM gives a childless joint a virtual tail 0.07 m (times the joint's
  world scale) beyond it along the parent→joint direction. A root bone without children
  would have no particle to move, so a synthetic ``<bone>_vrm_tail`` node is added there
  (``leaf_tails="all"`` adds one to every leaf, as UniVRM does).
* Radii: VRM 0.x radii are in the collider node's space, like MagicaCloth's (``r·|S.x|``);
  VRM 1.0 radii are world lengths at load (three-vrm's examples are authored so), so they
  are divided by the node's rest scale.
* A collider radius above MagicaCloth's inspector maximum (0.5 m), such as Godette's
  r = 1.0 sphere, is kept by default with a warning (``oversized_colliders="keep"``);
  ``"clamp"`` clamps it to 0.5 and ``"drop"`` leaves it out.
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from magica_py.io import coords
from magica_py.io.errors import AssetError
from magica_py.io.gltf import GltfRig, load_gltf, read_document
from magica_py.io.mapping import map_spring_parameters
from magica_py.io.quat import qfrom_to
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from magica_py.kernels import portable

VRM0_TAIL_LENGTH = 0.07          # UniVRM's virtual tail beyond a childless joint (m)
MAX_COLLIDER_RADIUS = 0.5        # MagicaCloth2 inspector slider maximum (docs/solver.md §G.1)
_AXES = "xyz"


def bones_label(names: list[str]) -> str:
    """A bone group's name from its root bones when the file has no comment: their common
    prefix without trailing separators (FrontHair_L, FrontHair_R -> FrontHair), else the first
    root's name ("" when that leaves fewer than 3 characters)."""
    if not names:
        return ""
    prefix = os.path.commonprefix(names).rstrip("_.-: ")
    label = prefix if len(prefix) >= 3 else (names[0] if len(names) == 1 else f"{names[0]}_and_{len(names) - 1}_more")
    return label if len(label) >= 3 else ""


@dataclass
class VrmCollider:
    """One collider in the shape of a YAML ``colliders`` entry (Unity axes, node space)."""

    name: str
    transform: str
    shape: str                         # sphere | capsule | plane
    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.0
    end_radius: float = 0.0
    length: float = 0.0                # capsule tip to tip
    direction: str = "y"
    source: str = ""                   # where it came from in the document

    def to_entry(self) -> dict:
        entry = {"name": self.name, "transform": self.transform, "center": [float(c) + 0.0 for c in self.center]}
        if self.shape == "sphere":
            entry["sphere"] = {"radius": float(self.radius)}
        elif self.shape == "capsule":
            entry["capsule"] = {"radius": float(self.radius), "end_radius": float(self.end_radius),
                                "length": float(self.length), "direction": self.direction,
                                "reverse": False, "aligned_on_center": True}
        else:
            entry["plane"] = {}
        return entry


@dataclass
class SpringChain:
    """One VRM chain (a root bone and its swinging descendants) with mapped parameters."""

    name: str
    group: str                         # VRM 0.x bone group / VRM 1.0 spring it belongs to
    root: str
    joints: list[str]                  # every simulated node, root first
    colliders: list[str]               # collider names
    vrm: dict                          # the VRM parameters (Unity axes)
    segment_length: float              # mean rest edge length (m), used by the mapping
    invalid: list[str] = field(default_factory=list)
    center: str | None = None


@dataclass
class VrmAvatar:
    rig: GltfRig
    spec_version: str                  # "0.x" | "1.0"
    humanoid: dict[str, str]           # VRM humanoid bone name → node name
    chains: list[SpringChain]
    colliders: list[VrmCollider]
    extra_bones: list[BoneSpec]        # synthetic tail and collider nodes
    warnings: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)

    @property
    def bones(self) -> list[BoneSpec]:
        return self.rig.bones + self.extra_bones

    @property
    def source(self) -> Path:
        return self.rig.source

    def cloth_entries(self, group_by: str = "group", prefix: str = "vrm_") -> list[dict]:
        """YAML ``cloths`` entries: one per VRM bone group / spring, or one per chain.

        Parameters follow ``mapping.map_spring_parameters``; the notes on what was
        approximated are in ``entry["notes"]`` (strip it before strict validation).
        """
        if group_by not in ("group", "chain"):
            raise ValueError(f"group_by must be 'group' or 'chain', got {group_by!r}")
        batches: dict[str, list[SpringChain]] = {}
        for chain in self.chains:
            batches.setdefault(chain.group if group_by == "group" else chain.name, []).append(chain)
        entries = []
        for key, chains in batches.items():
            first = chains[0]
            length = float(np.mean([c.segment_length for c in chains]))
            mapped = map_spring_parameters(first.vrm["stiffness"], first.vrm["gravity_power"], first.vrm["gravity_dir"],
                                           first.vrm["drag_force"], first.vrm["hit_radius"], length, first.center)
            colliders = []
            for c in chains:
                colliders += [n for n in c.colliders if n not in colliders]
            attributes = {name: "invalid" for c in chains for name in c.invalid}
            entry = {"name": f"{prefix}{key}", "type": "bone_cloth", "root_bones": [c.root for c in chains],
                     "connection": "line", "parameters": mapped.parameters, "colliders": colliders,
                     "collision_mode": "point" if colliders else "none", "notes": mapped.notes}
            if attributes:
                entry["bone_attributes"] = attributes
            entries.append(entry)
        return entries

    def collider_entries(self) -> list[dict]:
        return [c.to_entry() for c in self.colliders]


# ----------------------------------------------------------------------------- loading
def load_vrm(path, *, oversized_colliders: str = "keep", leaf_tails: str = "roots",
             unit_scale: float = 1.0, prefix: str = "") -> VrmAvatar:
    """Load a VRM 0.x / 1.0 file (or a glTF carrying ``VRMC_springBone``)."""
    if oversized_colliders not in ("keep", "clamp", "drop"):
        raise ValueError(f"oversized_colliders must be keep, clamp or drop, got {oversized_colliders!r}")
    if leaf_tails not in ("roots", "all"):
        raise ValueError(f"leaf_tails must be 'roots' or 'all', got {leaf_tails!r}")
    path = Path(path)
    document = read_document(path)
    ext = document[0].extensions or {}
    if "VRMC_springBone" in ext or "VRMC_vrm" in ext:
        version, axis = "1.0", "x"
    elif "VRM" in ext:
        version, axis = "0.x", "z"
    else:
        raise AssetError(path, "extensions", "no VRM data: expected extensions.VRM (VRM 0.x) or VRMC_vrm / VRMC_springBone (VRM 1.0)")
    rig = load_gltf(path, mirror_axis=axis, unit_scale=unit_scale, prefix=prefix, document=document)
    builder = _Builder(rig, unit_scale, oversized_colliders, leaf_tails)
    if version == "0.x":
        builder.read_vrm0(ext["VRM"])
    else:
        builder.read_vrm1(ext)
    for w in builder.warnings:
        warnings.warn(f"{path}: {w}", stacklevel=2)
    for s in builder.skipped:   # what has no MagicaCloth2 counterpart is left out, and said so
        warnings.warn(f"{path}: skipped {s}", stacklevel=2)
    return VrmAvatar(rig=rig, spec_version=version, humanoid=builder.humanoid, chains=builder.chains,
                     colliders=builder.colliders, extra_bones=builder.extra_bones,
                     warnings=builder.warnings, skipped=builder.skipped)


def _short(raw, limit: int = 80) -> str:
    text = repr(raw)
    return text if len(text) <= limit else text[:limit - 3] + "..."


class _Builder:
    def __init__(self, rig: GltfRig, unit_scale: float, oversized: str, leaf_tails: str):
        self.rig, self.path, self.unit_scale = rig, rig.source, unit_scale
        self.oversized, self.leaf_tails = oversized, leaf_tails
        self.hierarchy = TransformHierarchy(rig.bones)
        self.humanoid: dict[str, str] = {}
        self.chains: list[SpringChain] = []
        self.colliders: list[VrmCollider] = []
        self.extra_bones: list[BoneSpec] = []
        self.warnings: list[str] = []
        self.skipped: list[str] = []

    # -- helpers
    def unique_label(self, label: str, index: int) -> str:
        """Group / spring names become cloth names: two springs both called "Hair" stay apart."""
        used = {c.group for c in self.chains}
        return label if label not in used else f"{label}_{index}"

    def obj(self, raw, where: str) -> dict:
        """A JSON object of the extension ({} when absent); an AssetError if it is something else."""
        if raw is None:
            return {}
        if not isinstance(raw, dict):
            raise AssetError(self.path, where, f"expected an object, got {_short(raw)}")
        return raw

    def array(self, raw, where: str, objects: bool = True) -> list:
        """A JSON array of the extension ([] when absent), of objects unless ``objects`` is False."""
        if raw is None:
            return []
        if not isinstance(raw, list):
            raise AssetError(self.path, where, f"expected an array, got {_short(raw)}")
        if objects:
            for k, item in enumerate(raw):
                if not isinstance(item, dict):
                    raise AssetError(self.path, f"{where}[{k}]", f"expected an object, got {_short(item)}")
        return raw

    def node(self, index, where: str) -> str:
        return self.rig.node_name(index, where)

    def number(self, raw, where: str, default=None) -> float:
        if raw is None and default is not None:
            return float(default)
        if isinstance(raw, bool) or not isinstance(raw, (int, float)) or not np.isfinite(raw):
            raise AssetError(self.path, where, f"expected a number, got {raw!r}")
        return float(raw)

    def vector(self, raw, where: str, default=None) -> np.ndarray:
        if raw is None and default is not None:
            return np.asarray(default, dtype=np.float64)
        if isinstance(raw, dict):  # VRM 0.x {x, y, z}
            raw = [raw.get("x"), raw.get("y"), raw.get("z")]
        if not isinstance(raw, (list, tuple)) or len(raw) != 3:
            raise AssetError(self.path, where, f"expected 3 numbers, got {raw!r}")
        return np.array([self.number(v, f"{where}[{i}]") for i, v in enumerate(raw)])

    def subtree(self, name: str) -> list[str]:
        h = self.hierarchy
        return [h.names[i] for i in h.descendants(h.index(name))]

    def mean_edge(self, joints: list[str]) -> float:
        h = self.hierarchy
        lengths = []
        for name in joints[1:]:
            i = h.index(name) if name in h.index_of else None
            if i is None:
                continue
            lengths.append(portable.norm(h.world_position[i] - h.world_position[h.parent[i]]))
        extra = [b for b in self.extra_bones if b.name in joints]
        lengths += [portable.norm(b.position) for b in extra]
        return float(np.mean(lengths)) if lengths else VRM0_TAIL_LENGTH

    def add_tail(self, name: str) -> str:
        """UniVRM's virtual tail: 7 cm beyond a childless joint, along parent → joint."""
        h = self.hierarchy
        i = h.index(name)
        p = h.parent[i]
        direction = h.world_position[i] - h.world_position[p] if p >= 0 else np.array([0.0, -1.0, 0.0])
        n = portable.norm(direction)
        direction = direction / n if n > 1e-9 else np.array([0.0, -1.0, 0.0])
        world = h.world_position[i] + direction * VRM0_TAIL_LENGTH * self.unit_scale * abs(h.lossy_scale[i, 0])
        local = h.inverse_transform_point(i, world)
        tail = f"{name}_vrm_tail"
        self.extra_bones.append(BoneSpec(name=tail, parent=name, position=tuple(float(x) for x in local),
                                         tags={"synthetic": "vrm_tail"}))
        return tail

    def add_collider(self, collider: VrmCollider) -> None:
        h = self.hierarchy
        owner = collider.transform if collider.transform in h.index_of else collider.transform.split("#vrm_collider")[0]
        scale = abs(float(h.lossy_scale[h.index(owner), 0])) or 1.0
        limit = MAX_COLLIDER_RADIUS / scale     # compare world radii (MagicaCloth uses r·|S.x|)
        world = max(collider.radius, collider.end_radius) * scale
        if collider.shape != "plane" and world > MAX_COLLIDER_RADIUS:
            msg = (f"{collider.source}: radius {world:g} m exceeds "
                   f"MagicaCloth2's {MAX_COLLIDER_RADIUS:g} m inspector maximum (an authoring quirk)")
            if self.oversized == "drop":
                self.skipped.append(msg + "; dropped")   # said with the other skipped items
                return
            if self.oversized == "clamp":
                collider.radius = min(collider.radius, limit)
                collider.end_radius = min(collider.end_radius, limit)
                self.warnings.append(msg + f"; clamped to {MAX_COLLIDER_RADIUS:g} m")
            else:
                self.warnings.append(msg + "; kept as authored")
        self.colliders.append(collider)

    def synthetic_frame(self, node: str, k: int, position, up_direction) -> str:
        """A child of ``node`` at ``position`` whose +Y is ``up_direction`` (node space)."""
        name = f"{node}#vrm_collider{k}"
        rotation = qfrom_to([0.0, 1.0, 0.0], up_direction)
        self.extra_bones.append(BoneSpec(name=name, parent=node, position=tuple(float(x) for x in position),
                                         rotation=tuple(float(x) for x in rotation), tags={"synthetic": "vrm_collider"}))
        return name

    # -- VRM 0.x
    def read_vrm0(self, vrm: dict) -> None:
        base = "extensions.VRM"
        vrm = self.obj(vrm, base)
        humanoid = self.obj(vrm.get("humanoid"), f"{base}.humanoid")
        for k, hb in enumerate(self.array(humanoid.get("humanBones"), f"{base}.humanoid.humanBones")):
            if not isinstance(hb.get("bone"), str):
                raise AssetError(self.path, f"{base}.humanoid.humanBones[{k}].bone",
                                 f"expected a humanoid bone name, got {hb.get('bone')!r}")
            self.humanoid[hb.get("bone")] = self.node(hb.get("node"), f"{base}.humanoid.humanBones[{k}].node")
        sec = self.obj(vrm.get("secondaryAnimation") or {}, f"{base}.secondaryAnimation")
        group_colliders: list[list[str]] = []
        for g, group in enumerate(self.array(sec.get("colliderGroups"), f"{base}.secondaryAnimation.colliderGroups")):
            where = f"{base}.secondaryAnimation.colliderGroups[{g}]"
            node = self.node(group.get("node"), f"{where}.node")
            scale = self.unit_scale
            names = []
            for c, col in enumerate(self.array(group.get("colliders"), f"{where}.colliders")):
                cw = f"{where}.colliders[{c}]"
                offset = self.vector(col.get("offset"), f"{cw}.offset", (0, 0, 0)) * scale  # Unity axes already
                radius = self.number(col.get("radius"), f"{cw}.radius") * scale
                collider = VrmCollider(name=f"vrm_col{g}_{c}", transform=node, shape="sphere",
                                       center=tuple(offset), radius=radius, end_radius=radius, source=cw)
                before = len(self.colliders)
                self.add_collider(collider)
                if len(self.colliders) > before:
                    names.append(collider.name)
            group_colliders.append(names)
        for g, group in enumerate(self.array(sec.get("boneGroups"), f"{base}.secondaryAnimation.boneGroups")):
            where = f"{base}.secondaryAnimation.boneGroups[{g}]"
            bones = self.array(group.get("bones"), f"{where}.bones", objects=False)
            roots = [self.node(bone, f"{where}.bones[{b}]") for b, bone in enumerate(bones)]
            label = self.unique_label(group.get("comment") or bones_label(roots) or f"group{g}", g)
            center_index = group.get("center", -1)
            center = None if center_index in (None, -1) else self.node(center_index, f"{where}.center")
            params = {
                "stiffness": self.number(group.get("stiffiness", group.get("stiffness")), f"{where}.stiffiness", 1.0),
                "gravity_power": self.number(group.get("gravityPower"), f"{where}.gravityPower", 0.0),
                "gravity_dir": tuple(self.vector(group.get("gravityDir"), f"{where}.gravityDir", (0, -1, 0))),
                "drag_force": self.number(group.get("dragForce"), f"{where}.dragForce", 0.4),
                "hit_radius": self.number(group.get("hitRadius"), f"{where}.hitRadius", 0.02) * self.unit_scale,
            }
            colliders = []
            for j, gi in enumerate(self.array(group.get("colliderGroups"), f"{where}.colliderGroups", objects=False)):
                if not isinstance(gi, int) or not 0 <= gi < len(group_colliders):
                    raise AssetError(self.path, f"{where}.colliderGroups[{j}]",
                                     f"collider group {gi!r} does not exist ({len(group_colliders)} groups)")
                colliders += group_colliders[gi]
            for b, bone in enumerate(bones):
                root = self.node(bone, f"{where}.bones[{b}]")
                joints = self.subtree(root)
                leaves = [j for j in joints if not self.hierarchy.children[self.hierarchy.index(j)]]
                if len(joints) == 1 or self.leaf_tails == "all":
                    joints += [self.add_tail(j) for j in leaves]
                self.chains.append(SpringChain(name=root, group=label, root=root, joints=joints, colliders=list(colliders),
                                               vrm=dict(params), segment_length=self.mean_edge(joints), center=center))

    # -- VRM 1.0
    def read_vrm1(self, ext: dict) -> None:
        vrmc = self.obj(ext.get("VRMC_vrm"), "extensions.VRMC_vrm")
        humanoid = self.obj(vrmc.get("humanoid"), "extensions.VRMC_vrm.humanoid")
        human_bones = self.obj(humanoid.get("humanBones"), "extensions.VRMC_vrm.humanoid.humanBones")
        for bone, spec in human_bones.items():
            where = f"extensions.VRMC_vrm.humanoid.humanBones.{bone}"
            self.humanoid[bone] = self.node(self.obj(spec, where).get("node"), f"{where}.node")
        sb = ext.get("VRMC_springBone")
        if sb is None:
            return
        base = "extensions.VRMC_springBone"
        sb = self.obj(sb, base)
        collider_names: list[str | None] = []
        for c, col in enumerate(self.array(sb.get("colliders"), f"{base}.colliders")):
            collider_names.append(self.read_collider1(c, col, f"{base}.colliders[{c}]"))
        group_colliders = []
        for g, group in enumerate(self.array(sb.get("colliderGroups"), f"{base}.colliderGroups")):
            names = []
            for j, ci in enumerate(self.array(group.get("colliders"), f"{base}.colliderGroups[{g}].colliders", objects=False)):
                if not isinstance(ci, int) or not 0 <= ci < len(collider_names):
                    raise AssetError(self.path, f"{base}.colliderGroups[{g}].colliders[{j}]", f"collider {ci!r} does not exist")
                if collider_names[ci] is not None and collider_names[ci] not in names:
                    names.append(collider_names[ci])
            group_colliders.append(names)
        for s, spring in enumerate(self.array(sb.get("springs"), f"{base}.springs")):
            where = f"{base}.springs[{s}]"
            raw_joints = self.array(spring.get("joints"), f"{where}.joints")
            joints = [self.node(j.get("node"), f"{where}.joints[{k}].node") for k, j in enumerate(raw_joints)]
            label = self.unique_label(spring.get("name") or f"spring{s}", s)
            if len(joints) < 2:
                self.skipped.append(f"{where}: {len(joints)} joint(s), a VRM 1.0 spring needs a root and a tail")
                continue
            for k in range(1, len(joints)):
                i, p = self.hierarchy.index(joints[k]), self.hierarchy.index(joints[k - 1])
                if p not in self._ancestors(i):
                    raise AssetError(self.path, f"{where}.joints[{k}].node",
                                     f"{joints[k]!r} is not a descendant of the previous joint {joints[k - 1]!r}")
            simulated = raw_joints[:-1]   # the tail joint's parameters are not used (VRM 1.0 spec)
            values = {}
            for key, default in (("stiffness", 1.0), ("gravityPower", 0.0), ("dragForce", 0.5), ("hitRadius", 0.0)):
                vals = [self.number(j.get(key), f"{where}.joints[{k}].{key}", default) for k, j in enumerate(simulated)]
                if max(vals) - min(vals) > 1e-9:
                    self.warnings.append(f"{where}: {key} varies along the chain ({min(vals):g}..{max(vals):g}); the mean is used")
                values[key] = float(np.mean(vals))
            gdir = 0.0 + coords.position_to_unity(self.vector(simulated[0].get("gravityDir"), f"{where}.joints[0].gravityDir", (0, -1, 0)), "x")
            colliders = []
            for j, gi in enumerate(self.array(spring.get("colliderGroups"), f"{where}.colliderGroups", objects=False)):
                if not isinstance(gi, int) or not 0 <= gi < len(group_colliders):
                    raise AssetError(self.path, f"{where}.colliderGroups[{j}]", f"collider group {gi!r} does not exist")
                colliders += [n for n in group_colliders[gi] if n not in colliders]
            center = None if spring.get("center") is None else self.node(spring.get("center"), f"{where}.center")
            params = {"stiffness": values["stiffness"], "gravity_power": values["gravityPower"], "gravity_dir": tuple(gdir),
                      "drag_force": values["dragForce"], "hit_radius": values["hitRadius"] * self.unit_scale}
            invalid = [n for n in self.subtree(joints[0]) if n not in joints]
            self.chains.append(SpringChain(name=label, group=label, root=joints[0], joints=joints, colliders=colliders,
                                           vrm=params, segment_length=self.mean_edge(joints), invalid=invalid, center=center))

    def _ancestors(self, i: int) -> set[int]:
        out, p = set(), self.hierarchy.parent[i]
        while p >= 0:
            out.add(int(p))
            p = self.hierarchy.parent[p]
        return out

    def read_collider1(self, c: int, col: dict, where: str) -> str | None:
        node = self.node(col.get("node"), f"{where}.node")
        i = self.hierarchy.index(node)
        world_scale = abs(float(self.hierarchy.lossy_scale[i, 0])) or 1.0
        sw = f"{where}.shape"
        shape = self.obj(col.get("shape"), sw)
        extended = ((col.get("extensions") or {}).get("VRMC_springBone_extended_collider") or {}).get("shape")
        if extended:
            shape, sw = extended, f"{where}.extensions.VRMC_springBone_extended_collider.shape"
        if len(shape) != 1:
            raise AssetError(self.path, sw, f"expected exactly one of sphere, capsule, plane; got {sorted(shape)}")
        kind, spec = next(iter(shape.items()))
        spec = self.obj(spec, f"{sw}.{kind}")
        if spec.get("inside"):
            self.skipped.append(f"{sw}.{kind}: inside {kind} has no MagicaCloth2 counterpart (colliders only push out)")
            return None
        s = self.unit_scale
        offset = coords.position_to_unity(self.vector(spec.get("offset"), f"{sw}.{kind}.offset", (0, 0, 0)), "x") * s
        name = f"vrm_col{c}_{node}"
        if kind == "sphere":
            r = self.number(spec.get("radius"), f"{sw}.sphere.radius", 0.0) * s / world_scale
            self.add_collider(VrmCollider(name, node, "sphere", tuple(offset), r, r, source=sw))
        elif kind == "capsule":
            r = self.number(spec.get("radius"), f"{sw}.capsule.radius", 0.0) * s / world_scale
            tail = coords.position_to_unity(self.vector(spec.get("tail"), f"{sw}.capsule.tail", (0, 0, 0)), "x") * s
            d = tail - offset
            length = portable.norm(d)
            mid = 0.5 * (offset + tail)
            if length < 1e-9:
                self.add_collider(VrmCollider(name, node, "sphere", tuple(offset), r, r, source=sw))
                return name
            axis = int(np.argmax(np.abs(d)))
            if abs(d[axis]) >= length * (1.0 - 1e-9):
                transform, center, direction = node, tuple(mid), _AXES[axis]
            else:
                transform, center, direction = self.synthetic_frame(node, c, mid, d), (0.0, 0.0, 0.0), "y"
            self.add_collider(VrmCollider(name, transform, "capsule", center, r, r, length + 2.0 * r, direction, source=sw))
        elif kind == "plane":
            normal = coords.position_to_unity(self.vector(spec.get("normal"), f"{sw}.plane.normal", (0, 0, 1)), "x")
            if portable.norm(normal) < 1e-9:
                raise AssetError(self.path, f"{sw}.plane.normal", "is a zero vector")
            normal = normal / portable.norm(normal)
            if normal[1] > 1.0 - 1e-9:
                transform, center = node, tuple(offset)
            else:
                transform, center = self.synthetic_frame(node, c, offset, normal), (0.0, 0.0, 0.0)
            self.colliders.append(VrmCollider(name, transform, "plane", center, source=sw))
        else:
            self.skipped.append(f"{sw}.{kind}: unknown collider shape")
            return None
        return name
