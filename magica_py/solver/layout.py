"""The solver's global model: every team's ``ClothModel`` concatenated into one SoA.

One chunk per team, team-local indices offset to global ones, so that one numba call
processes every team (tech-notes LAYOUT). Built once when the cloth set changes (not in the
frame path). ``-1`` stays ``-1`` when offsetting. Read-only after building.

Ragged data use ``*_start``/``*_count`` pairs: per team (``team_*``) ranges into the
per-item arrays, and per particle ranges into link data (distance, children, triangles).
"""
from __future__ import annotations

import numpy as np

from magica_py.solver.fields import F64, I32, U8, make_soa

V3 = (3,)
Q4 = (4,)

MODEL_FIELDS = [
    # per team
    ("team_particle_start", "team", (), I32, "first particle of the team"),
    ("team_particle_count", "team", (), I32, ""),
    ("team_baseline_start", "team", (), I32, "first baseline of the team"),
    ("team_baseline_count", "team", (), I32, ""),
    ("team_center_start", "team", (), I32, "range in center_fixed"),
    ("team_center_count", "team", (), I32, ""),
    ("team_edge_start", "team", (), I32, "range in edges"),
    ("team_edge_count", "team", (), I32, ""),
    ("team_triangle_start", "team", (), I32, "range in triangles"),
    ("team_triangle_count", "team", (), I32, ""),
    ("team_bend_start", "team", (), I32, "range in bend_*"),
    ("team_bend_count", "team", (), I32, ""),
    ("team_volume_start", "team", (), I32, "range in volume_*"),
    ("team_volume_count", "team", (), I32, ""),
    ("team_component_transform", "team", (), I32, "hierarchy node of the component"),
    ("team_init_scale", "team", V3, F64, "component lossy scale at build"),
    ("team_init_local_gravity", "team", V3, F64, "gravity reference in the center frame (C.2)"),
    ("team_has_lines", "team", (), U8, "1: the proxy has lines (E.2 runs)"),
    # per particle
    ("transform_index", "particle", (), I32, "hierarchy node of the bone"),
    ("particle_team", "particle", (), I32, "team of the particle"),
    ("attribute", "particle", (), U8, "Fixed 1, Move 2, InvalidMotion 8, DisableCollision 0x10, ZeroDistance 0x20, Triangle 0x80"),
    ("parent", "particle", (), I32, "parent particle or -1"),
    ("root_index", "particle", (), I32, "root particle of a Move particle or -1"),
    ("depth", "particle", (), F64, "[0,1] normalised arc length from the root"),
    ("local_position", "particle", V3, F64, "cloth-local build position"),
    ("local_normal", "particle", V3, F64, ""),
    ("local_tangent", "particle", V3, F64, ""),
    ("bind_rotation", "particle", Q4, F64, "qinv(rot_from(n, t)) (B.4.8)"),
    ("vertex_to_transform_rotation", "particle", Q4, F64, "v2t (B.4.7)"),
    ("skin_bind_pose", "particle", (4, 4), F64, "inverse(TRS bone) @ init render local-to-world"),
    ("baseline_local_position", "particle", V3, F64, "rest position in the parent's frame (B.7)"),
    ("baseline_local_rotation", "particle", Q4, F64, "rest rotation relative to the parent (B.7)"),
    ("child_start", "particle", (), I32, "range in child_data"),
    ("child_count", "particle", (), I32, ""),
    ("distance_start", "particle", (), I32, "range in distance_target/rest"),
    ("distance_count", "particle", (), I32, ""),
    ("vertex_triangle_start", "particle", (), I32, "range in vertex_triangle_data"),
    ("vertex_triangle_count", "particle", (), I32, ""),
    # per baseline
    ("baseline_flags", "baseline", (), U8, "bit 0x01 IncludeLine"),
    ("baseline_start", "baseline", (), I32, "range in baseline_data"),
    ("baseline_count", "baseline", (), I32, ""),
    # link data
    ("baseline_data", "baseline_entry", (), I32, "particles of each baseline, parent first"),
    ("center_fixed", "center", (), I32, "fixed particles defining the center"),
    ("child_data", "child", (), I32, "children particles"),
    ("distance_target", "distance", (), I32, "partner particle"),
    ("distance_rest", "distance", (), F64, "signed rest length (+ vertical, - horizontal, 0 zero)"),
    ("edges", "edge", (2,), I32, ""),
    ("triangles", "triangle", (3,), I32, "oriented"),
    ("triangle_uv", "triangle", (3, 2), F64, "uv of the three corners (tangent reconstruction)"),
    ("vertex_triangle_data", "vertex_triangle", (), I32, "triangles of each vertex"),
    ("vertex_triangle_flip", "vertex_triangle", (), U8, "bit 1 flip normal, bit 2 flip tangent"),
    ("bend_vertices", "bend", (4,), I32, "v0 v1 v2 v3"),
    ("bend_rest_angle", "bend", (), F64, "rad"),
    ("bend_sign", "bend", (), F64, "+-1"),
    ("volume_vertices", "volume", (4,), I32, ""),
    ("volume_rest", "volume", (), F64, "1000 x rest volume"),
]
SolverModel = make_soa("SolverModel", MODEL_FIELDS)

INCLUDE_LINE = 0x01


def _get(model, name, default=None):
    value = getattr(model, name, None)
    return default if value is None else value


def _ranges(counts):
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.zeros(len(counts), dtype=np.int64)
    if len(counts):
        starts[1:] = np.cumsum(counts)[:-1]
    return starts


def build_solver_model(models: list) -> "SolverModel":
    """Concatenate team models (``build.ClothModel`` field names) into one ``SolverModel``."""
    parts: dict[str, list] = {name: [] for name, *_ in MODEL_FIELDS}
    offsets = {k: 0 for k in ("particle", "baseline", "baseline_entry", "center", "child",
                              "distance", "edge", "triangle", "vertex_triangle", "bend", "volume")}

    def off(a, base):
        a = np.asarray(a, dtype=np.int64)
        return np.where(a >= 0, a + base, -1)

    for team, m in enumerate(models):
        n = int(m.particle_count)
        p0 = offsets["particle"]
        bl_count = np.asarray(m.baseline_count)
        tri = np.asarray(_get(m, "triangles", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
        edges = np.asarray(_get(m, "edges", np.zeros((0, 2))), dtype=np.int64).reshape(-1, 2)
        bend = np.asarray(_get(m, "bend_vertices", np.zeros((0, 4))), dtype=np.int64).reshape(-1, 4)
        vol = np.asarray(_get(m, "volume_vertices", np.zeros((0, 4))), dtype=np.int64).reshape(-1, 4)
        center = np.asarray(m.center_fixed, dtype=np.int64)
        lines = _get(m, "lines", np.zeros((0, 2)))
        vt_count = np.asarray(_get(m, "vertex_triangle_count", np.zeros(n)), dtype=np.int64)
        vt_start = np.asarray(_get(m, "vertex_triangle_start", _ranges(vt_count)), dtype=np.int64)
        vt_data = np.asarray(_get(m, "vertex_triangle_data", np.zeros(0)), dtype=np.int64)
        vt_flip = np.asarray(_get(m, "vertex_triangle_flip", np.zeros(len(vt_data))), dtype=np.int64)
        uv = np.asarray(_get(m, "triangle_uv", np.zeros((len(tri), 3, 2))), dtype=np.float64)
        if uv.shape != (len(tri), 3, 2):  # per-vertex uv (N, 2): gather per triangle corner
            uv = uv.reshape(-1, 2)[tri] if len(tri) else np.zeros((0, 3, 2))

        parts["team_particle_start"].append([p0])
        parts["team_particle_count"].append([n])
        parts["team_baseline_start"].append([offsets["baseline"]])
        parts["team_baseline_count"].append([len(bl_count)])
        parts["team_center_start"].append([offsets["center"]])
        parts["team_center_count"].append([len(center)])
        parts["team_edge_start"].append([offsets["edge"]])
        parts["team_edge_count"].append([len(edges)])
        parts["team_triangle_start"].append([offsets["triangle"]])
        parts["team_triangle_count"].append([len(tri)])
        parts["team_bend_start"].append([offsets["bend"]])
        parts["team_bend_count"].append([len(bend)])
        parts["team_volume_start"].append([offsets["volume"]])
        parts["team_volume_count"].append([len(vol)])
        parts["team_component_transform"].append([int(m.component_transform)])
        parts["team_init_scale"].append(np.asarray(m.init_scale, dtype=np.float64).reshape(1, 3))
        parts["team_init_local_gravity"].append(
            np.asarray(m.init_local_gravity_direction, dtype=np.float64).reshape(1, 3))
        parts["team_has_lines"].append([1 if len(lines) > 0 else 0])

        parts["transform_index"].append(m.transform_index)
        parts["particle_team"].append(np.full(n, team))
        parts["attribute"].append(m.attribute)
        parts["parent"].append(off(m.parent, p0))
        parts["root_index"].append(off(m.root_index, p0))
        parts["depth"].append(m.depth)
        for name in ("local_position", "local_normal", "local_tangent", "bind_rotation",
                     "vertex_to_transform_rotation", "skin_bind_pose", "baseline_local_position",
                     "baseline_local_rotation"):
            parts[name].append(getattr(m, name))
        parts["child_start"].append(np.asarray(m.child_start) + offsets["child"])
        parts["child_count"].append(m.child_count)
        parts["distance_start"].append(np.asarray(m.distance_start) + offsets["distance"])
        parts["distance_count"].append(m.distance_count)
        parts["vertex_triangle_start"].append(vt_start + offsets["vertex_triangle"])
        parts["vertex_triangle_count"].append(vt_count)

        parts["baseline_flags"].append(m.baseline_flags)
        parts["baseline_start"].append(np.asarray(m.baseline_start) + offsets["baseline_entry"])
        parts["baseline_count"].append(bl_count)
        parts["baseline_data"].append(off(m.baseline_data, p0))
        parts["center_fixed"].append(off(center, p0))
        parts["child_data"].append(off(m.child_data, p0))
        parts["distance_target"].append(off(m.distance_target, p0))
        parts["distance_rest"].append(m.distance_rest)
        parts["edges"].append(off(edges, p0))
        parts["triangles"].append(off(tri, p0))
        parts["triangle_uv"].append(uv)
        parts["vertex_triangle_data"].append(off(vt_data, offsets["triangle"]))
        parts["vertex_triangle_flip"].append(vt_flip)
        parts["bend_vertices"].append(off(bend, p0))
        parts["bend_rest_angle"].append(_get(m, "bend_rest_angle", np.zeros(len(bend))))
        parts["bend_sign"].append(_get(m, "bend_sign", np.ones(len(bend))))
        parts["volume_vertices"].append(off(vol, p0))
        parts["volume_rest"].append(_get(m, "volume_rest", np.zeros(len(vol))))

        offsets["particle"] += n
        offsets["baseline"] += len(bl_count)
        offsets["baseline_entry"] += len(np.asarray(m.baseline_data))
        offsets["center"] += len(center)
        offsets["child"] += len(np.asarray(m.child_data))
        offsets["distance"] += len(np.asarray(m.distance_target))
        offsets["edge"] += len(edges)
        offsets["triangle"] += len(tri)
        offsets["vertex_triangle"] += len(vt_data)
        offsets["bend"] += len(bend)
        offsets["volume"] += len(vol)

    arrays = {}
    for name, _per, shape, dtype, _doc in MODEL_FIELDS:
        chunks = [np.asarray(c, dtype=dtype).reshape((-1,) + tuple(shape)) for c in parts[name]]
        a = np.concatenate(chunks) if chunks else np.zeros((0,) + tuple(shape), dtype=dtype)
        a = np.ascontiguousarray(a, dtype=dtype)
        a.flags.writeable = False
        arrays[name] = a
    return SolverModel(**arrays)
