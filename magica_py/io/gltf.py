"""glTF 2.0 / GLB (and VRM, which is GLB) → rig bones, skin joints and animation clips.

``load_gltf(path)`` returns a ``GltfRig``: the nodes of the default scene as
``BoneSpec``s (unique names, parents, local TRS converted to Unity convention by
``magica_py.io.coords`` and scaled to metres by ``unit_scale``), which nodes are skin
joints, and every node animation as a ``Clip`` (translation / rotation / scale channels,
``LINEAR`` / ``STEP`` / ``CUBICSPLINE`` samplers; morph-target ``weights`` are ignored).

Parsing uses pygltflib for the container; the GLB header and chunk sizes are checked first
so a truncated file gets a clear ``AssetError`` rather than a struct or JSON error.
"""
from __future__ import annotations

import base64
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pygltflib

from magica_py.io import coords
from magica_py.io.clip import Clip, Track
from magica_py.io.errors import AssetError
from magica_py.io.quat import qfrom_matrix, qnormalize
from magica_py.scene.hierarchy import BoneSpec
from magica_py.kernels import portable

_COMPONENT_DTYPE = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
                    5125: np.uint32, 5126: np.float32}
_NORMALIZE_DIVISOR = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_TYPE_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_INTERPOLATION = {"LINEAR": "linear", "STEP": "step", "CUBICSPLINE": "cubicspline"}


@dataclass
class GltfRig:
    """A glTF scene as rig data (Unity convention, metres)."""

    source: Path
    names: list[str]                 # per glTF node index: the unique (prefixed) bone name, None if not in the scene
    bones: list[BoneSpec]            # scene nodes, parents before children
    joints: set[str]                 # names of nodes used as skin joints
    skins: list[dict]                # {"name", "joints": [names], "skeleton": name | None}
    clips: dict[str, Clip]
    mirror_axis: str
    unit_scale: float
    document: pygltflib.GLTF2       # scene graph, skins, animations, buffers, extensions (no meshes/accessors)
    extensions: dict = field(default_factory=dict)  # document-level extensions, raw JSON (file convention)
    notes: list[str] = field(default_factory=list)

    def node_name(self, index: int, where: str = "") -> str:
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(self.names):
            raise AssetError(self.source, where, f"node index {index!r} does not exist (the file has {len(self.names)} nodes)")
        name = self.names[index]
        if name is None:
            raise AssetError(self.source, where, f"node {index} is not part of the loaded scene")
        return name

    def clip(self, name: str) -> Clip:
        if name not in self.clips:
            raise AssetError(self.source, f"animations[name={name!r}]",
                             f"no animation named {name!r}; the file has {sorted(self.clips) or 'none'}")
        return self.clips[name]

    @property
    def bone_names(self) -> list[str]:
        return [b.name for b in self.bones]


# ----------------------------------------------------------------------------- container
# Top-level glTF arrays handed to pygltflib. Accessors, buffer views and meshes stay raw JSON:
# pygltflib's dataclass decoding costs about 1 ms per object (wuson.glb's 709 accessors and
# 709 buffer views took 1 s) and a rig import only reads a few of them.
_DOCUMENT_KEYS = ("asset", "scene", "scenes", "nodes", "skins", "animations", "buffers",
                  "extensions", "extensionsUsed", "extensionsRequired", "extras")


def read_document(path) -> tuple[pygltflib.GLTF2, bytes | None, dict]:
    """Parse a .gltf / .glb / .vrm file: the pygltflib document (scene graph, skins,
    animations, buffers, extensions), the GLB binary chunk and the raw JSON."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise AssetError(path, "", f"cannot read the file ({exc.strerror or exc})") from None
    if data[:4] == b"glTF":
        return _read_glb(path, data)
    try:
        text = data.decode("utf-8-sig")
        raw = json.loads(text)
    except UnicodeDecodeError:
        raise AssetError(path, "", "neither a GLB container (no 'glTF' magic) nor UTF-8 glTF JSON") from None
    except json.JSONDecodeError as exc:
        raise AssetError(path, f"line {exc.lineno} column {exc.colno}", f"invalid glTF JSON: {exc.msg}") from None
    _check_top_level(path, raw)
    return _document(path, raw), None, raw


def _read_glb(path: Path, data: bytes):
    if len(data) < 20:
        raise AssetError(path, "GLB header", f"truncated: {len(data)} bytes, a GLB needs a 12-byte header and a JSON chunk")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise AssetError(path, "GLB header", f"container version {version}, expected 2")
    if length > len(data):
        raise AssetError(path, "GLB header", f"truncated: the header declares {length} bytes but the file has {len(data)}")
    offset, chunks = 12, {}
    while offset < length:
        if offset + 8 > length:
            raise AssetError(path, f"GLB chunk at byte {offset}", "truncated chunk header")
        chunk_length, chunk_type = struct.unpack_from("<I4s", data, offset)
        if offset + 8 + chunk_length > length:
            raise AssetError(path, f"GLB chunk {chunk_type!r} at byte {offset}",
                             f"truncated: declares {chunk_length} bytes, only {length - offset - 8} remain")
        chunks.setdefault(chunk_type, data[offset + 8:offset + 8 + chunk_length])
        offset += 8 + chunk_length
    if b"JSON" not in chunks:
        raise AssetError(path, "GLB chunks", "no JSON chunk")
    try:
        raw = json.loads(chunks[b"JSON"].decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise AssetError(path, "GLB JSON chunk", f"invalid JSON ({exc})") from None
    _check_top_level(path, raw)
    return _document(path, raw), chunks.get(b"BIN\x00"), raw


def _document(path: Path, raw: dict) -> pygltflib.GLTF2:
    try:
        return pygltflib.GLTF2.gltf_from_json(json.dumps({k: raw[k] for k in _DOCUMENT_KEYS if k in raw}))
    except (TypeError, ValueError, AttributeError, KeyError) as exc:
        # a value of the wrong type (a string where numbers belong, ...): pygltflib's decoder
        # does not say where; the nodes' TRS are checked again with their path at load
        raise AssetError(path, "glTF JSON", f"a value of the wrong type for glTF 2.0 ({type(exc).__name__}: {exc})") from None


def _check_top_level(path: Path, raw) -> None:
    if not isinstance(raw, dict):
        raise AssetError(path, "$", f"expected a glTF JSON object, got {type(raw).__name__}")
    if "asset" not in raw:
        raise AssetError(path, "asset", "missing (every glTF 2.0 file has asset.version)")
    for key in ("scenes", "nodes", "skins", "animations", "buffers", "accessors", "bufferViews"):
        items = raw.get(key)
        if items is None:
            continue
        if not isinstance(items, list):
            raise AssetError(path, key, f"expected an array of objects, got {type(items).__name__}")
        for k, item in enumerate(items):
            if not isinstance(item, dict):
                raise AssetError(path, f"{key}[{k}]", f"expected an object, got {item!r}")
    for i, node in enumerate(raw.get("nodes") or []):
        for key, size in (("translation", 3), ("rotation", 4), ("scale", 3), ("matrix", 16)):
            value = node.get(key)
            if value is not None and not (isinstance(value, list) and all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)):
                text = repr(value)
                raise AssetError(path, f"nodes[{i}].{key}", f"expected {size} numbers, got "
                                 f"{text if len(text) <= 80 else text[:77] + '...'}")
    scenes = raw.get("scenes")
    if not isinstance(scenes, list) or not scenes:
        raise AssetError(path, "scenes", "no scene: expected a non-empty 'scenes' array naming the root nodes")
    scene = raw.get("scene", 0)
    if not isinstance(scene, int) or not 0 <= scene < len(scenes):
        raise AssetError(path, "scene", f"{scene!r} is not an index into scenes (0..{len(scenes) - 1})")


class _Buffers:
    """Buffer bytes by index: the GLB binary chunk, data: URIs or files beside the document."""

    def __init__(self, path: Path, doc: pygltflib.GLTF2, glb_bin: bytes | None, raw: dict):
        self.path, self.doc, self.glb_bin, self.cache = path, doc, glb_bin, {}
        self.accessors = raw.get("accessors") or []
        self.views = raw.get("bufferViews") or []

    def get(self, index: int) -> bytes:
        if index not in self.cache:
            where = f"buffers[{index}]"
            if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(self.doc.buffers):
                raise AssetError(self.path, where, f"does not exist (the file has {len(self.doc.buffers)} buffers)")
            buf = self.doc.buffers[index]
            if buf.uri is None:
                if self.glb_bin is None:
                    raise AssetError(self.path, where, "has no uri and the file has no GLB binary chunk")
                data = self.glb_bin
            elif buf.uri.startswith("data:"):
                try:
                    data = base64.b64decode(buf.uri.split(",", 1)[1], validate=True)
                except (IndexError, ValueError) as exc:
                    raise AssetError(self.path, f"{where}.uri", f"invalid base64 data: URI ({exc})") from None
            else:
                file = self.path.parent / buf.uri
                try:
                    data = file.read_bytes()
                except OSError:
                    raise AssetError(self.path, f"{where}.uri", f"cannot read {file}") from None
            if not isinstance(buf.byteLength, int) or isinstance(buf.byteLength, bool) or buf.byteLength < 0:
                raise AssetError(self.path, f"{where}.byteLength", f"expected the buffer's size in bytes, got {buf.byteLength!r}")
            if len(data) < buf.byteLength:
                raise AssetError(self.path, where, f"truncated: byteLength {buf.byteLength}, only {len(data)} bytes available")
            self.cache[index] = data
        return self.cache[index]

    def accessor(self, index: int, where: str) -> np.ndarray:
        """Accessor data as float64 (count, width) (normalized integers dequantized)."""
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(self.accessors):
            raise AssetError(self.path, where, f"accessor {index!r} does not exist ({len(self.accessors)} accessors)")
        acc = self.accessors[index]
        where = f"accessors[{index}]"
        if acc.get("sparse") is not None:
            raise AssetError(self.path, f"{where}.sparse", "sparse accessors are not supported for animation data")
        width = _TYPE_WIDTH.get(acc.get("type"))
        dtype = _COMPONENT_DTYPE.get(acc.get("componentType"))
        count = acc.get("count")
        if width is None or dtype is None or not isinstance(count, int) or count < 0:
            raise AssetError(self.path, where, f"unsupported or missing type/componentType/count "
                             f"({acc.get('type')}/{acc.get('componentType')}/{count})")
        if acc.get("bufferView") is None:
            return np.zeros((count, width))
        v = acc["bufferView"]
        if not isinstance(v, int) or not 0 <= v < len(self.views):
            raise AssetError(self.path, f"{where}.bufferView", f"buffer view {v!r} does not exist")
        view = self.views[v]
        data = self.get(view.get("buffer", 0))
        itemsize = np.dtype(dtype).itemsize
        stride = view.get("byteStride") or itemsize * width
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        end = start + stride * (count - 1) + itemsize * width if count else start
        if start < 0 or view.get("byteOffset", 0) < 0 or acc.get("byteOffset", 0) < 0:
            raise AssetError(self.path, where, f"negative byteOffset (accessor {acc.get('byteOffset', 0)}, "
                             f"buffer view {view.get('byteOffset', 0)}); expected offsets >= 0")
        if end > view.get("byteOffset", 0) + view.get("byteLength", 0) or end > len(data):
            raise AssetError(self.path, where, f"reads bytes {start}..{end} beyond its buffer view / buffer")
        values = np.ndarray((count, width), dtype=np.dtype(dtype).newbyteorder("<"), buffer=data,
                            offset=start, strides=(stride, itemsize))
        out = values.astype(np.float64)
        if acc.get("normalized") and acc["componentType"] in _NORMALIZE_DIVISOR:
            out = np.maximum(out / _NORMALIZE_DIVISOR[acc["componentType"]], -1.0)
        return out


# ----------------------------------------------------------------------------- loading
def load_gltf(path, *, unit_scale: float = 1.0, mirror_axis: str = "x", prefix: str = "",
              load_animations: bool = True, document=None) -> GltfRig:
    """Load the default scene of a glTF / GLB file as Unity-convention rig data.

    ``unit_scale`` multiplies every translation (0.01 for a centimetre asset such as the
    Khronos Fox); ``mirror_axis`` is the handedness conversion (see ``coords``);
    ``prefix`` is prepended to every bone name (several copies of one asset in a scene);
    ``document`` is a ``read_document(path)`` result already at hand (avoids a second parse).
    """
    path = Path(path)
    doc, glb_bin, raw = document if document is not None else read_document(path)
    buffers = _Buffers(path, doc, glb_bin, raw)
    names, parent, order = _scene_nodes(path, doc, prefix)
    bones = []
    for i in order:
        t, r, s = _node_trs(path, doc.nodes[i], i)
        t = coords.position_to_unity(t * unit_scale, mirror_axis)
        r = coords.rotation_to_unity(r, mirror_axis)
        p = parent.get(i)
        bones.append(BoneSpec(name=names[i], parent=None if p is None else names[p],
                              position=tuple(float(x) for x in t), rotation=tuple(float(x) for x in r),
                              scale=tuple(float(x) for x in s), tags={"gltf_node": i}))
    joints, skins = set(), []
    for k, skin in enumerate(doc.skins or []):
        skin_joints = []
        for j, node in enumerate(skin.joints or []):
            name = _name_or_raise(path, names, node, f"skins[{k}].joints[{j}]")
            joints.add(name)
            skin_joints.append(name)
        skeleton = None if skin.skeleton is None else _name_or_raise(path, names, skin.skeleton, f"skins[{k}].skeleton")
        skins.append({"name": skin.name or f"skin{k}", "joints": skin_joints, "skeleton": skeleton})
    for b in bones:
        b.tags["joint"] = b.name in joints
    clips = _load_clips(path, doc, buffers, names, unit_scale, mirror_axis) if load_animations else {}
    return GltfRig(source=path, names=names, bones=bones, joints=joints, skins=skins, clips=clips,
                   mirror_axis=mirror_axis, unit_scale=unit_scale, document=doc,
                   extensions=dict(doc.extensions or {}))


def _name_or_raise(path, names, node, where) -> str:
    if not isinstance(node, int) or not 0 <= node < len(names):
        raise AssetError(path, where, f"node index {node!r} does not exist (the file has {len(names)} nodes)")
    if names[node] is None:
        raise AssetError(path, where, f"node {node} is not part of the loaded scene")
    return names[node]


def _scene_nodes(path: Path, doc: pygltflib.GLTF2, prefix: str):
    """Unique names of the scene's nodes, their parents and a parents-first order."""
    n = len(doc.nodes)
    parent: dict[int, int] = {}
    for i, node in enumerate(doc.nodes):
        for j, c in enumerate(node.children or []):
            if not isinstance(c, int) or not 0 <= c < n:
                raise AssetError(path, f"nodes[{i}].children[{j}]", f"node index {c!r} does not exist (the file has {n} nodes)")
            if c in parent:
                raise AssetError(path, f"nodes[{i}].children[{j}]", f"node {c} already has parent {parent[c]} (glTF nodes form a tree)")
            parent[c] = i
    scene_index = doc.scene if doc.scene is not None else 0
    roots = doc.scenes[scene_index].nodes or []
    order, stack, seen = [], list(reversed(roots)), set()
    for k, r in enumerate(roots):
        if not isinstance(r, int) or not 0 <= r < n:
            raise AssetError(path, f"scenes[{scene_index}].nodes[{k}]", f"node index {r!r} does not exist")
        if r in parent:
            raise AssetError(path, f"scenes[{scene_index}].nodes[{k}]", f"root node {r} has a parent ({parent[r]})")
    while stack:
        i = stack.pop()
        if i in seen:
            raise AssetError(path, f"nodes[{i}]", "reached twice: the node graph has a cycle")
        seen.add(i)
        order.append(i)
        stack.extend(reversed(doc.nodes[i].children or []))
    names: list[str | None] = [None] * n
    used: set[str] = set()
    for i in order:
        base = doc.nodes[i].name or f"node{i}"
        name = f"{prefix}{base}"
        if name in used:
            name = f"{prefix}{base}.{i}"
        used.add(name)
        names[i] = name
    return names, parent, order


def _node_trs(path: Path, node, i: int):
    """Local translation, rotation (xyzw) and scale of a node in the file's convention."""
    if node.matrix is not None:
        m = _numbers(path, node.matrix, f"nodes[{i}].matrix")
        if m.shape != (16,) or not np.all(np.isfinite(m)):
            raise AssetError(path, f"nodes[{i}].matrix", f"expected 16 finite numbers, got {m.tolist()}")
        m = m.reshape(4, 4).T  # glTF stores matrices column-major
        t = m[:3, 3].copy()
        basis = m[:3, :3]
        s = portable.norm(basis.T)
        if portable.determinant3(basis) < 0:
            s[0] = -s[0]
        if np.any(np.abs(s) < 1e-12):
            raise AssetError(path, f"nodes[{i}].matrix", "has a zero scale (not decomposable into TRS)")
        r = qfrom_matrix(basis / s)
        return t, r, s
    t = _numbers(path, node.translation if node.translation is not None else (0, 0, 0), f"nodes[{i}].translation")
    r = _numbers(path, node.rotation if node.rotation is not None else (0, 0, 0, 1), f"nodes[{i}].rotation")
    s = _numbers(path, node.scale if node.scale is not None else (1, 1, 1), f"nodes[{i}].scale")
    for key, v, size in (("translation", t, 3), ("rotation", r, 4), ("scale", s, 3)):
        if v.shape != (size,) or not np.all(np.isfinite(v)):
            raise AssetError(path, f"nodes[{i}].{key}", f"expected {size} finite numbers, got {v.tolist()}")
    if portable.norm(r) < 1e-9:
        raise AssetError(path, f"nodes[{i}].rotation", "is a zero quaternion")
    return t, qnormalize(r), s


def _numbers(path: Path, raw, where: str) -> np.ndarray:
    """A JSON array of numbers as float64 (an AssetError naming ``where`` if it is not one)."""
    try:
        return np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError):
        raise AssetError(path, where, f"expected an array of numbers, got {raw!r}") from None


def _load_clips(path, doc, buffers, names, unit_scale, mirror_axis) -> dict[str, Clip]:
    clips: dict[str, Clip] = {}
    for a, anim in enumerate(doc.animations or []):
        tracks, notes = [], []
        for c, channel in enumerate(anim.channels or []):
            where = f"animations[{a}].channels[{c}]"
            target = channel.target
            if target is None or target.node is None:
                notes.append(f"{where}: no target node (extension-driven), skipped")
                continue
            if target.path not in ("translation", "rotation", "scale"):
                notes.append(f"{where}: path {target.path!r} ignored")
                continue
            if not isinstance(target.node, int) or not 0 <= target.node < len(names):
                raise AssetError(path, f"{where}.target.node", f"node index {target.node!r} does not exist (the file has {len(names)} nodes)")
            node = names[target.node]
            if node is None:
                notes.append(f"{where}: node {target.node} is outside the scene, skipped")
                continue
            if not 0 <= channel.sampler < len(anim.samplers):
                raise AssetError(path, f"{where}.sampler", f"sampler {channel.sampler} does not exist")
            sampler = anim.samplers[channel.sampler]
            swhere = f"animations[{a}].samplers[{channel.sampler}]"
            interp = _INTERPOLATION.get(sampler.interpolation or "LINEAR")
            if interp is None:
                raise AssetError(path, f"{swhere}.interpolation", f"{sampler.interpolation!r}, expected LINEAR, STEP or CUBICSPLINE")
            times = buffers.accessor(sampler.input, f"{swhere}.input")[:, 0]
            values = buffers.accessor(sampler.output, f"{swhere}.output")
            width = 4 if target.path == "rotation" else 3
            if values.shape[1] != width:
                raise AssetError(path, f"{swhere}.output", f"{target.path} needs {width} components per key, got {values.shape[1]}")
            if len(times) == 0:
                raise AssetError(path, f"{swhere}.input", "has no keys")
            for key, data in (("input", times), ("output", values)):
                flat = data.reshape(len(data), -1)
                bad = np.flatnonzero(~np.isfinite(flat).all(axis=1))
                if bad.size:
                    raise AssetError(path, f"{swhere}.{key}", f"element {bad[0]} is not finite ({flat[bad[0]].tolist()}); "
                                     f"expected finite key {'times' if key == 'input' else 'values'}")
            if np.any(np.diff(times) <= 0.0):
                raise AssetError(path, f"{swhere}.input", "key times must strictly increase")
            expected = 3 * len(times) if interp == "cubicspline" else len(times)
            if len(values) != expected:
                raise AssetError(path, f"{swhere}.output", f"{len(values)} values for {len(times)} keys ({interp} needs {expected})")
            if interp == "cubicspline":
                in_t, values, out_t = values[0::3], values[1::3], values[2::3]
            else:
                in_t = out_t = None
            if target.path == "rotation":   # keys (not tangents) are unit quaternions in glTF
                zero = np.flatnonzero(np.sum(values * values, axis=1) < 1e-18)
                if zero.size:
                    k = int(zero[0]) * (3 if interp == "cubicspline" else 1) + (1 if interp == "cubicspline" else 0)
                    raise AssetError(path, f"{swhere}.output", f"element {k} is a zero quaternion; expected unit "
                                     "rotations")
            convert = {"translation": lambda v: coords.position_to_unity(v * unit_scale, mirror_axis),
                       "rotation": lambda v: coords.rotation_to_unity(v, mirror_axis),
                       "scale": lambda v: coords.scale_to_unity(v, mirror_axis)}[target.path]
            values = convert(values)
            if target.path == "rotation" and interp != "cubicspline":
                values = qnormalize(values)
            tracks.append(Track(node=node, path=target.path, times=times, values=values, interpolation=interp,
                                in_tangents=None if in_t is None else convert(in_t),
                                out_tangents=None if out_t is None else convert(out_t)))
        name = anim.name or f"animation{a}"
        if name in clips:
            name = f"{name}.{a}"
        clips[name] = Clip(name=name, tracks=tracks, source=path, notes=notes)
    return clips
