"""Constraint build data (docs/solver.md §B.9, §D.7, §0.3) and the parameter switches of §F.

"Model only what a scene needs": every builder here is called only when the cloth's
parameters switch its feature on; ``plan_features`` says which and why not.
"""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from magica_py.build.proxy import FIXED, MOVE, _starts
from magica_py.params import default_parameters
from magica_py.build.topology import bending_pairs, edge_triangles, key_table, shear_links
from magica_py.kernels import portable

CURVE_SAMPLES = 16
ZERO_DISTANCE = 1e-8

CURVE_PARAMETERS = ("damping", "radius", "distance.stiffness", "angle_restoration.stiffness",
                    "angle_limit.limit_angle", "motion.max_distance", "motion.backstop_distance")


def parameter(params: Mapping | None, key: str):
    """The cloth's value for ``key``, or its default of the parameter table
    (``params.default_parameters``)."""
    if params is not None and key in params:
        return params[key]
    return default_parameters()[key]


def wants_bending(params: Mapping | None) -> bool:
    """Does a mesh cloth with these parameters build triangle bending and volume pairs (§D.7:
    only when ``triangle_bending.stiffness`` is above 1e-8)?"""
    return float(parameter(params, "triangle_bending.stiffness")) > 1e-8


def curve_samples(value) -> np.ndarray:
    """16-sample depth table of a curve parameter (§0.3, ``ConvertFloatArray``).

    Accepts a ``params.Curve`` (anything with ``.samples``), a plain number (flat curve) or
    a tuple ``(value, start, end, use_curve)`` (the linear ``CurveSerializeData`` constructor).
    The samples are the raw parameter curve: conversions such as damping ×0.2 or restoration
    ×0.2 belong to the solver (§F.1 "conversion" column)."""
    samples = getattr(value, "samples", None)
    if samples is not None:
        out = np.asarray(samples, dtype=np.float64).reshape(-1)
        if out.shape != (CURVE_SAMPLES,):
            raise ValueError(f"curve has {out.size} samples, expected {CURVE_SAMPLES}")
        return out
    if isinstance(value, (tuple, list)):
        v, start, end, use = value
        if not use:
            return np.full(CURVE_SAMPLES, float(v))
        t = np.arange(CURVE_SAMPLES) / (CURVE_SAMPLES - 1)
        s0, s1 = min(max(start, 0.0), 1.0), min(max(end, 0.0), 1.0)
        return float(v) * (s0 + (s1 - s0) * t)
    return np.full(CURVE_SAMPLES, float(value))


def curve_tables(params) -> dict:
    return {key: _frozen(curve_samples(parameter(params, key))) for key in CURVE_PARAMETERS}


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


# ----------------------------------------------------------------------------- distance
def distance_links(attribute, parent, pos, neighbor_start, neighbor_count, neighbor_data,
                   triangles, tri_normals, edges):
    """Vertical and horizontal distance links per vertex, CSR with signed rest (§B.9).

    Returns (distance_start, distance_count, distance_target, distance_rest): per vertex the
    vertical links (parent/child, rest > 0) first, then horizontal and shear links (rest < 0),
    a rest of exactly 0 marking a zero-distance link."""
    n = attribute.shape[0]
    valid = (attribute & (FIXED | MOVE)) != 0
    move = (attribute & MOVE) != 0
    src = np.repeat(np.arange(n), neighbor_count)
    dst = neighbor_data.astype(np.int64)
    keep = valid[src] & valid[dst] & (move[src] | move[dst])
    src, dst = src[keep], dst[keep]
    vertical = (parent[dst] == src) | (parent[src] == dst)
    # shear links across near-flat, near-square quads (triangle modes only)
    shear_src = shear_dst = np.zeros(0, dtype=np.int64)
    if triangles.shape[0]:
        edge_pairs, et_start, et_count, et_data, _ = edge_triangles(triangles, n)
        worst = int((et_count * (et_count - 1)).sum())
        out_src = np.empty(worst, dtype=np.int64)
        out_dst = np.empty(worst, dtype=np.int64)
        k = shear_links(pos, triangles, tri_normals, edge_pairs, et_start, et_count, et_data,
                        valid, move, src, dst, out_src, out_dst, key_table(src.shape[0] + worst))
        shear_src, shear_dst = out_src[:k], out_dst[:k]
    src = np.concatenate([src, shear_src])
    dst = np.concatenate([dst, shear_dst])
    vertical = np.concatenate([vertical, np.zeros(len(shear_src), dtype=bool)])
    order = np.lexsort((~vertical, src))  # by vertex, vertical first, insertion order kept
    src, dst, vertical = src[order], dst[order], vertical[order]
    length = portable.norm(pos[src] - pos[dst])
    rest = np.where(vertical, length, -length)
    rest[length < ZERO_DISTANCE] = 0.0
    count = np.bincount(src, minlength=n).astype(np.int32)
    return _starts(count), count, dst.astype(np.int32), rest


# ----------------------------------------------------------------------------- bending
def bending_and_volume(attribute, triangles, pos_local, local_to_world, want_volume=True):
    """Triangle-pair bending and volume data (§D.7 "Build").

    Returns (bend_vertices (Kb,4), bend_rest_angle (Kb,) rad, bend_sign (Kb,) ±1,
    volume_vertices (Kv,4), volume_rest (Kv,) = 1000·signed tetra volume in world m³)."""
    valid = (attribute & (FIXED | MOVE)) != 0
    move = (attribute & MOVE) != 0
    world = portable.transform_points(local_to_world, pos_local)
    edge_pairs, et_start, et_count, et_data, _ = edge_triangles(triangles, pos_local.shape[0])
    worst = int((et_count * (et_count - 1) // 2).sum())
    bend = np.empty((worst, 4), dtype=np.int32)
    angle = np.empty(worst)
    sign = np.empty(worst)
    vol = np.empty((worst, 4), dtype=np.int32)
    vol_rest = np.empty(worst)
    nb, nv = bending_pairs(pos_local, world, triangles, edge_pairs, et_start, et_count, et_data,
                           valid, move, want_volume, bend, angle, sign, vol, vol_rest, key_table(worst))
    return bend[:nb].copy(), angle[:nb].copy(), sign[:nb].copy(), vol[:nv].copy(), vol_rest[:nv].copy()


def rest_volumes(pos_local, volume_vertices, local_to_world) -> np.ndarray:
    """1000 x signed tetrahedron volume of each volume pair in world space (§D.7); the same
    formula as ``bending_pairs`` (used when a cached model is re-targeted to another instance)."""
    world = portable.transform_points(local_to_world, pos_local)
    v = volume_vertices
    if v.shape[0] == 0:
        return np.zeros(0)
    w0, w1, w2, w3 = world[v[:, 0]], world[v[:, 1]], world[v[:, 2]], world[v[:, 3]]
    return 1000.0 / 6.0 * portable.dot3(np.cross(w1 - w0, w2 - w0), w3 - w0)
