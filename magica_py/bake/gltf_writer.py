"""Write captured motion as a glTF animation, into a copy of the rig's own file.

For a rig loaded from a glTF / GLB / VRM file the output is that file (meshes, skins,
materials, textures, VRM extensions, earlier animations) with one more animation whose
channels drive the rig's nodes, so it opens in Blender or an engine with its mesh and skin.
Bones the file does not have (VRM virtual tails and collider frames, bones a scene adds
with ``bones`` / ``parts``, generated rigs) are appended as new nodes under their parent's
node (or as new roots of the default scene). Without a source file the output holds just
those nodes and the animation.

Conversion (the inverse of ``io.gltf.load_gltf``): translations ``coords.position_from_unity``
divided by the rig's ``unit_scale``, rotations ``coords.rotation_from_unity``, scales as is,
with the rig's mirror axis (X for glTF and VRM 1.0, Z for VRM 0.x). Keys are float32 (glTF
accessors), one per rendered frame, ``LINEAR`` (rotations slerp); a channel that does not
change over the bake is written as one key. All buffers of the source are merged into one
binary (the GLB ``BIN`` chunk, or ``FILE.bin`` beside a ``.gltf``); image files referenced
by a ``.gltf`` source are re-pointed relative to the output.
"""
from __future__ import annotations

import json
import os
import urllib.parse
from pathlib import Path

import numpy as np
import pygltflib

from magica_py import atomic
from magica_py.io import coords
from magica_py.io.gltf import _Buffers, read_document

FLOAT = 5126
ALIGN = 4


class _Blob:
    """The output binary: source buffers first, then the animation data, 4-byte aligned."""

    def __init__(self):
        self.parts: list[bytes] = []
        self.length = 0

    def add(self, data: bytes) -> int:
        offset = self.length
        self.parts.append(data)
        self.length += len(data)
        pad = (-self.length) % ALIGN
        if pad:
            self.parts.append(b"\x00" * pad)
            self.length += pad
        return offset

    def bytes(self) -> bytes:
        return b"".join(self.parts)


def _source_document(source: Path | None, out: Path):
    """(raw JSON, blob) of the source with its buffers merged into one, or an empty document."""
    blob = _Blob()
    if source is None:
        raw = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"name": "magica_bake", "nodes": []}],
               "nodes": []}
        return raw, blob
    doc, glb_bin, raw = read_document(source)
    raw = json.loads(json.dumps(raw))      # our own copy to edit
    buffers = _Buffers(source, doc, glb_bin, raw)
    base = [blob.add(buffers.get(i)[:doc.buffers[i].byteLength]) for i in range(len(doc.buffers))]
    for view in raw.get("bufferViews") or []:
        view["byteOffset"] = view.get("byteOffset", 0) + base[view.get("buffer", 0)]
        view["buffer"] = 0
    for image in raw.get("images") or []:
        uri = image.get("uri")
        if uri and not uri.startswith("data:"):
            target = source.parent / urllib.parse.unquote(uri)
            image["uri"] = urllib.parse.quote(Path(os.path.relpath(target, out.parent)).as_posix())
    return raw, blob


def write_gltf(path, motion, *, source=None, node_of: dict[str, int] | None = None, unit_scale: float = 1.0,
               mirror_axis: str = "x", animation_name: str = "magica_bake") -> list[str]:
    """Write ``motion`` (``capture.CapturedMotion``) as an animation to ``path`` (.glb, .vrm:
    binary container; .gltf: JSON + ``.bin``). ``source``: the rig's file (None: a new file);
    ``node_of``: bone name → node index in ``source`` (bones not in it are appended).
    Returns notes."""
    path = Path(path)
    source = None if source is None else Path(source)
    node_of = dict(node_of or {})
    raw, blob = _source_document(source, path)
    notes = []
    nodes = raw.setdefault("nodes", [])
    scene = raw["scenes"][raw.get("scene", 0) or 0]
    scene.setdefault("nodes", [])
    to_file_t = lambda v: coords.position_from_unity(v, mirror_axis) / unit_scale  # noqa: E731
    to_file_r = lambda v: coords.rotation_from_unity(v, mirror_axis)             # noqa: E731

    # bones the file does not have: new nodes under their parent's node (parents come first)
    index = {}
    appended = []
    for j, name in enumerate(motion.names):
        if name in node_of:
            index[j] = node_of[name]
            continue
        node = {"name": name, "translation": [float(x) for x in to_file_t(motion.rest_position[j])],
                "rotation": [float(x) for x in to_file_r(motion.rest_rotation[j])],
                "scale": [float(x) for x in motion.rest_scale[j]]}
        nodes.append(node)
        index[j] = len(nodes) - 1
        appended.append(name)
        p = int(motion.parent[j])
        if p >= 0:
            nodes[index[p]].setdefault("children", []).append(index[j])
        else:
            scene["nodes"].append(index[j])
    # an animated node may not carry a matrix (glTF 2.0 §3.5.3): give it its rest TRS instead
    # (the importer decomposed the matrix into exactly this pose)
    for j in range(len(motion.names)):
        node = nodes[index[j]]
        if "matrix" in node:
            del node["matrix"]
            node["translation"] = [float(x) for x in to_file_t(motion.rest_position[j])]
            node["rotation"] = [float(x) for x in to_file_r(motion.rest_rotation[j])]
            node["scale"] = [float(x) for x in motion.rest_scale[j]]
    if appended and source is not None:
        notes.append(f"{len(appended)} bones not in {source.name} appended as new nodes "
                     f"({', '.join(appended[:4])}{' ...' if len(appended) > 4 else ''})")

    accessors = raw.setdefault("accessors", [])
    views = raw.setdefault("bufferViews", [])
    start = blob.length
    chunks: list[tuple[int, np.ndarray]] = []    # (accessor index, float32 data) in blob order

    def accessor(data: np.ndarray, kind: str, bounds: bool = False) -> int:
        data = np.ascontiguousarray(data, dtype="<f4")
        entry = {"bufferView": len(views), "componentType": FLOAT, "count": int(data.shape[0]), "type": kind,
                 "byteOffset": 0}
        if bounds:
            entry["min"] = [float(x) for x in np.atleast_1d(data.min(axis=0))]
            entry["max"] = [float(x) for x in np.atleast_1d(data.max(axis=0))]
        accessors.append(entry)
        chunks.append((len(accessors) - 1, data))
        return len(accessors) - 1

    times = motion.times
    frames = int(times.shape[0])
    if frames == 0:
        raise ValueError("nothing to write: the capture has no frame")
    all_keys = accessor(times.reshape(-1, 1), "SCALAR", bounds=True)
    one_key = accessor(np.zeros((1, 1)), "SCALAR", bounds=True)
    samplers, channels = [], []
    translation = to_file_t(motion.local_position)
    rotation = to_file_r(motion.local_rotation)
    constant = 0
    for j in range(len(motion.names)):
        for path_name, values, kind in (("translation", translation[:, j], "VEC3"),
                                        ("rotation", rotation[:, j], "VEC4"),
                                        ("scale", motion.local_scale[:, j], "VEC3")):
            still = bool(np.all(values == values[:1]))
            if path_name == "scale" and still and np.all(values[0] == motion.rest_scale[j]):
                continue  # a scale that never leaves the rest scale needs no channel
            constant += still
            output = accessor(values[:1] if still else values, kind)
            samplers.append({"input": one_key if still else all_keys, "output": output, "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": index[j], "path": path_name}})
    # one buffer view for all animation data; accessors point into it
    view_index = len(views)
    for acc, data in chunks:
        accessors[acc]["bufferView"] = view_index
        accessors[acc]["byteOffset"] = blob.add(data.tobytes()) - start
    views.append({"buffer": 0, "byteOffset": start, "byteLength": blob.length - start,
                  "name": f"{animation_name} keys"})
    names = {a.get("name") for a in raw.get("animations") or []}
    name, k = animation_name, 1
    while name in names:
        name, k = f"{animation_name}.{k}", k + 1
    if name != animation_name:
        notes.append(f"the file already has an animation {animation_name!r}: written as {name!r}")
    raw.setdefault("animations", []).append({"name": name, "samplers": samplers, "channels": channels})
    notes.append(f"animation {name!r}: {len(channels)} channels on {len(motion.names)} nodes, {frames} keys "
                 f"({constant} constant channels as one key)")
    raw.setdefault("asset", {})["generator"] = "magica-py bake"

    data = blob.bytes()
    binary = path.suffix.lower() in (".glb", ".vrm")
    if binary:
        raw["buffers"] = [{"byteLength": len(data)}]
    else:
        bin_name = path.with_suffix(".bin").name
        raw["buffers"] = [{"byteLength": len(data), "uri": urllib.parse.quote(bin_name)}]
    gltf = pygltflib.GLTF2.gltf_from_json(json.dumps(raw))
    # whole or not at all (magica_py/atomic.py); a .gltf's buffer is renamed just before it
    with atomic.replacing(path) as tmp:
        if binary:
            gltf.set_binary_blob(data)
            gltf.save_binary(str(tmp))
        else:
            with atomic.replacing(path.with_suffix(".bin")) as bin_tmp:
                bin_tmp.write_bytes(data)
                gltf.save_json(str(tmp))
    return notes
