"""``ClothModel``: the read-only build output of one cloth (docs/architecture.md "Cloth model").

Team-local indices; vertex i = bone i in RenderSetupData order (docs/solver.md §B.1).  Every array is
``writeable=False`` and written once by ``build_cloth``; the simulation state lives elsewhere.
Positions are cloth-local (the component's space at build, scale included), in metres.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, fields
from types import MappingProxyType

import numpy as np

from magica_py.build.proxy import FIXED, MOVE, ZERO_DISTANCE


@dataclass(frozen=True, eq=False)
class ClothModel:
    # --- identity
    name: str                          # cloth name (ClothSpec.name)
    connection_mode: str               # "line" | "automatic_mesh" | "sequential_loop_mesh" | "sequential_non_loop_mesh"
    particle_count: int                # N
    transform_index: np.ndarray        # (N,) int32 hierarchy node of each particle
    component_transform: int           # hierarchy node of the cloth component
    bone_names: tuple                  # (N,) names of the bones, vertex order
    root_vertices: np.ndarray          # (R,) int32 vertex of each root bone, root-list order
    # --- per particle (§B.2-§B.8)
    attribute: np.ndarray              # (N,) uint8 Fixed 0x01 Move 0x02 InvalidMotion 0x08 DisableCollision 0x10 ZeroDistance 0x20 Triangle 0x80
    parent: np.ndarray                 # (N,) int32 parent vertex or -1
    root_index: np.ndarray             # (N,) int32 first non-Move ancestor of a Move vertex, else -1
    root_length: np.ndarray            # (N,) float64 m arc length to root_index (cloth-local)
    child_start: np.ndarray            # (N,) int32 CSR into child_data
    child_count: np.ndarray            # (N,) int32
    child_data: np.ndarray             # (N - roots,) int32 children, increasing vertex index
    depth: np.ndarray                  # (N,) float64 normalised arc length from the root, [0, 1]
    local_position: np.ndarray         # (N,3) float64 m cloth-local build position
    local_normal: np.ndarray           # (N,3) unit cloth-local normal (bone +Y, or triangle normal)
    local_tangent: np.ndarray          # (N,3) unit cloth-local tangent (bone +Z, or triangle binormal)
    bind_rotation: np.ndarray          # (N,4) xyzw qinv(rot_from(n, t))
    vertex_to_transform_rotation: np.ndarray  # (N,4) xyzw v2t (§B.4.7)
    skin_bind_pose: np.ndarray         # (N,4,4) inverse(TRS(P,R,S)) @ init_render_local_to_world
    vertex_uv: np.ndarray              # (N,2) spherical uv (mesh modes), zeros otherwise
    # --- baselines (§B.6, §B.7)
    baseline_local_position: np.ndarray  # (N,3) m rest position relative to the parent frame
    baseline_local_rotation: np.ndarray  # (N,4) xyzw rest rotation relative to the parent
    baseline_flags: np.ndarray         # (B,) uint8 IncludeLine 0x01
    baseline_start: np.ndarray         # (B,) int32 into baseline_data
    baseline_count: np.ndarray         # (B,) int32
    baseline_data: np.ndarray          # (L,) int32 vertices, start vertex first, pre-order
    center_fixed: np.ndarray           # (F,) int32 fixed vertices defining the center (§B.4.4)
    local_center_position: np.ndarray  # (3,) m mean of center_fixed positions (0 if none)
    # --- topology
    edges: np.ndarray                  # (E,2) int32 sorted pairs
    lines: np.ndarray                  # (Ln,2) int32 sorted pairs
    triangles: np.ndarray              # (T,3) int32 oriented by the flood fill
    neighbor_start: np.ndarray         # (N,) int32 CSR vertex adjacency
    neighbor_count: np.ndarray         # (N,) int32
    neighbor_data: np.ndarray          # (2E,) int32
    vertex_triangle_start: np.ndarray  # (N,) int32 CSR, at most 7 triangles per vertex
    vertex_triangle_count: np.ndarray  # (N,) int32
    vertex_triangle_data: np.ndarray   # (S,) int32 triangle indices
    vertex_triangle_flip: np.ndarray   # (S,) uint8 0x01 negate normal, 0x02 negate tangent (§E.3)
    triangle_uv: np.ndarray            # (T,3,2) uv of each triangle corner
    # --- constraints (§B.9, §D.7)
    distance_start: np.ndarray         # (N,) int32 CSR
    distance_count: np.ndarray         # (N,) int32
    distance_target: np.ndarray        # (D,) int32 other vertex
    distance_rest: np.ndarray          # (D,) float64 m, + vertical, - horizontal, 0 zero-distance
    bend_vertices: np.ndarray          # (Kb,4) int32 v0, v1 (opposite), v2, v3 (shared edge)
    bend_rest_angle: np.ndarray        # (Kb,) float64 rad
    bend_sign: np.ndarray              # (Kb,) float64 ±1
    volume_vertices: np.ndarray        # (Kv,4) int32
    volume_rest: np.ndarray            # (Kv,) float64 1000 x signed tetra volume (world m³ at build)
    collider_index: np.ndarray         # (C,) int32 indices into scene.colliders
    collider_slot_capacity: int        # C rounded up to a multiple of 8 (ExpandedColliderCount)
    collision_mode: str                # "none" | "point" | "edge" (what was built)
    # --- cloth-local space (§B.1, §B.10, §C.2)
    init_render_local_to_world: np.ndarray   # (4,4)
    init_render_world_to_local: np.ndarray   # (4,4)
    init_render_rotation: np.ndarray   # (4,) xyzw
    init_scale: np.ndarray             # (3,) component lossy scale at build
    init_local_gravity_direction: np.ndarray  # (3,) unit
    average_vertex_distance: float     # m, stride-sampled (§B.4)
    max_vertex_distance: float         # m
    aabb_min: np.ndarray               # (3,) m cloth-local
    aabb_max: np.ndarray               # (3,)
    # --- what was built
    curves: MappingProxyType           # parameter key -> (16,) depth table (raw curve, §0.3)
    features: MappingProxyType         # feature -> bool
    skipped: MappingProxyType          # feature -> reason it was not built
    topology_key: str = ""             # hash of the topology arrays (crowd batching)

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v.flags.writeable = False


TOPOLOGY_FIELDS = ("attribute", "parent", "root_index", "child_start", "child_count", "child_data",
                   "baseline_flags", "baseline_start", "baseline_count", "baseline_data", "center_fixed",
                   "edges", "lines", "triangles", "neighbor_start", "neighbor_count", "neighbor_data",
                   "vertex_triangle_start", "vertex_triangle_count", "vertex_triangle_data",
                   "vertex_triangle_flip", "distance_start", "distance_count", "distance_target",
                   "bend_vertices", "volume_vertices")


def topology_hash(arrays: dict, features: dict) -> str:
    """Hash of the index arrays, built features and collider count: equal keys mean teams
    that one batched kernel can process side by side (docs/tech-notes.md LAYOUT)."""
    h = hashlib.blake2b(digest_size=16)
    for name in TOPOLOGY_FIELDS:
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    # which colliders a team uses is per instance; only how many shapes the kernel
    h.update(repr((sorted(features.items()), len(arrays["collider_index"]))).encode())
    return h.hexdigest()


def describe(model: ClothModel) -> list[str]:
    """Human-readable summary of what was built and skipped (``magica-py info``)."""
    n = model.particle_count
    fixed = int(np.count_nonzero(model.attribute & FIXED))
    move = int(np.count_nonzero(model.attribute & MOVE))
    zero = int(np.count_nonzero(model.attribute & ZERO_DISTANCE))
    out = [
        f"cloth {model.name!r}: {n} particles ({fixed} fixed, {move} move, {n - fixed - move} invalid), "
        f"mode {model.connection_mode}, {len(model.root_vertices)} roots",
        f"  topology: {len(model.edges)} edges, {len(model.lines)} lines, {len(model.triangles)} triangles, "
        f"{len(model.baseline_start)} baselines, {len(model.center_fixed)} center-fixed",
        f"  vertex distance: average {model.average_vertex_distance:.4g} m, max {model.max_vertex_distance:.4g} m"
        + (f"; {zero} zero-distance vertices" if zero else ""),
    ]
    counts = {
        "distance": f"{len(model.distance_target)} links "
                    f"({int(np.count_nonzero(model.distance_rest > 0))} vertical, "
                    f"{int(np.count_nonzero(model.distance_rest < 0))} horizontal, "
                    f"{int(np.count_nonzero(model.distance_rest == 0))} zero)",
        "tether": f"{int(np.count_nonzero(model.root_index >= 0))} particles",
        "bending": f"{len(model.bend_vertices)} pairs",
        "volume": f"{len(model.volume_vertices)} pairs",
        "collision_point": _plural(len(model.collider_index), "collider"),
        "collision_edge": f"{_plural(len(model.collider_index), 'collider')}, {len(model.edges)} edges",
        "angle": " + ".join(k.split("_")[1] for k in ("angle_restoration", "angle_limit")
                            if model.features.get(k)) + f" over {len(model.baseline_start)} baselines",
    }
    parts = ("angle_restoration", "angle_limit")  # summarised by "angle"
    for feature, built in model.features.items():
        if built and feature not in parts:
            out.append(f"  built   {feature}" + (f": {counts[feature]}" if feature in counts else ""))
    for feature, reason in model.skipped.items():
        if feature == "angle" or feature not in parts or model.features.get("angle"):
            out.append(f"  skipped {feature}: {reason}")
    return out


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")
