"""BoneCloth build path (docs/solver.md §B): root bones -> RenderSetupData -> VirtualMesh -> proxy mesh ->
constraint data -> read-only ``ClothModel`` (the solver's ``blocks.BlockLayout`` places each
model, one team, in a block of teams of its kind).

``build_cloth(hierarchy, spec)`` duck-types ``spec`` (a ``ClothSpec``): it reads ``name``,
``root_bones``, ``component``, ``connection_mode``, ``parameters`` (a mapping of dotted keys;
curves carry ``.samples``), ``colliders``, ``collision_mode`` and ``bone_attributes``.

Zero-length and coincident bones: a bone whose position equals its parent's gets the
ZeroDistance attribute and a distance link of rest 0 (§B.7, §B.9); no NaN is produced
(vertex frames come from the bone axes, depth uses arc length, degenerate triangles are
dropped by the 1e-6 squared-length test of §B.3 and skipped in bending).

Deviations from the reference, deliberate and documented:
* collinear candidate triangles (sin of the corner angle < 1e-6) are not created: the
  reference would keep a zero-area triangle whose normal is undefined;
* a root listed below another root, a root without children, a zero scale and more than
  127 bones on one hierarchy level (mesh modes) raise ``BuildError`` instead of being
  silently dropped or overflowing a fixed-size list; links beyond 31 per vertex are dropped;
* cloth-local positions and bone axes are chained from the local poses below the component
  instead of ``W2L · P`` (equal up to rounding, tests/test_build_features.py) so that
  identical rigs give bit-identical models wherever they stand (crowds share a
  ``topology_key`` and the ``ModelCache``); the world path is used when the component is
  not above the roots;
* ``MathUtility.TriangleAngle`` is taken as the fold angle of the pair (0 when flat), and
  the stable orders the reference leaves to C# hash sets are insertion orders.

Modules: ``render_setup`` (§B.1), ``virtual_mesh`` (§B.2-B.3), ``topology`` (edge-triangle
maps and the triangle-pair kernels), ``proxy`` (§B.4-B.8), ``constraints`` (§B.9, §D.7,
§0.3), ``model`` (``ClothModel``, ``describe``).
"""
from __future__ import annotations

import dataclasses
import hashlib
import math
from collections import OrderedDict
from collections.abc import Hashable
from types import MappingProxyType

import numpy as np

from magica_py.build import constraints, proxy, virtual_mesh
from magica_py.build.errors import BuildError
from magica_py.build.model import ClothModel, describe, topology_hash
from magica_py.build.render_setup import collect_transforms
from magica_py.kernels import portable

__all__ = ["BuildError", "ClothModel", "ModelCache", "build_cloth", "describe"]

MAX_PROXY_COUNT = 32767  # MaxProxyMeshVertexCount / Edge / Triangle (§0.4)
EXPANDED_COLLIDER_COUNT = 8


def _check_limit(cloth, what, count, names):
    if count > MAX_PROXY_COUNT:
        raise BuildError(cloth, f"{count} {what} exceed the reference limit of {MAX_PROXY_COUNT} "
                                f"(roots {list(names)[:4]}); split the cloth into several cloths")


class ModelCache:
    """Reuses the build of identical cloths (crowds of instanced rigs).

    Two cloths share an entry when everything the build reads is bit-identical: the bones'
    pose chained below the component, the tree, root order, mode, attributes (per vertex),
    parameters, collider count and the component's scale.  A hit costs the bone collection
    plus the per-instance fields (transforms, colliders, skin bind poses, world-space rest
    volumes) and gives exactly the arrays a fresh build would give (tests/test_build_cache.py).
    Parameters that are not hashable disable the cache for that cloth.  At most
    ``max_entries`` models are kept (least recently used dropped first)."""

    def __init__(self, max_entries: int = 64):
        self.models: OrderedDict[str, ClothModel] = OrderedDict()
        self.max_entries = max_entries
        self.hits = 0
        self.misses = 0

    def get(self, key):
        model = self.models.get(key)
        if model is not None:
            self.models.move_to_end(key)
            self.hits += 1
        return model

    def put(self, key, model) -> None:
        self.misses += 1
        self.models[key] = model
        while len(self.models) > self.max_entries:
            self.models.popitem(last=False)


DEFAULT_CACHE = ModelCache()
_DEFAULT = object()


def build_cloth(hierarchy, spec, cache=_DEFAULT) -> ClothModel:
    """Build the read-only model of one BoneCloth from the hierarchy's current (rest) pose.

    ``cache``: a ``ModelCache`` (default: the module's ``DEFAULT_CACHE``), or None to always
    build from scratch."""
    if cache is _DEFAULT:
        cache = DEFAULT_CACHE
    name = str(getattr(spec, "name", "cloth"))
    mode = str(getattr(spec, "connection_mode", "line"))
    if mode not in virtual_mesh.CONNECTION_MODES:
        raise BuildError(name, f"connection_mode {mode!r}: expected one of {virtual_mesh.CONNECTION_MODES}")
    setup = collect_transforms(hierarchy, name, getattr(spec, "root_bones", ()), getattr(spec, "component", None))
    root_names = [setup.bone_names[v] for v in setup.root_vertices]
    _check_limit(name, "bones (proxy vertices)", setup.count, root_names)
    key = _cache_key(setup, spec, mode) if cache is not None else None
    cached = cache.get(key) if key is not None else None
    if cached is not None:
        return _instance_of(cached, setup, spec)
    model = _build(setup, spec, name, mode, root_names)
    if key is not None:
        cache.put(key, model)
    return model


def _cache_key(setup, spec, mode):
    params = getattr(spec, "parameters", None)
    vertex_of = {int(t): i for i, t in enumerate(setup.transform_index)}
    attributes = tuple(sorted((vertex_of.get(int(k), -1 - int(k)), str(v))
                              for k, v in (getattr(spec, "bone_attributes", None) or {}).items()))
    try:
        param_key = hash(params if params is None or isinstance(params, Hashable)
                         else frozenset(params.items()))
    except TypeError:
        return None
    h = hashlib.blake2b(digest_size=20)
    for a in (setup.component_position, setup.component_rotation, setup.parent_vertex,
              setup.root_vertices, setup.init_scale):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr((setup.child_vertices, mode, attributes, param_key, repr(params),
                   len(tuple(getattr(spec, "colliders", ()) or ())), getattr(spec, "collision_mode", "point"))).encode())
    return h.hexdigest()


def _instance_of(model: ClothModel, setup, spec) -> ClothModel:
    """A cached model re-targeted at another instance's transforms and colliders."""
    _, _, _, skin_bind_pose = virtual_mesh.import_bones(setup)
    colliders = model.collider_index
    if len(colliders):
        colliders = np.asarray(tuple(spec.colliders), dtype=np.int32).reshape(-1)
    return dataclasses.replace(
        model, collider_index=colliders, name=setup.cloth_name, transform_index=setup.transform_index,
        component_transform=setup.component_transform, bone_names=setup.bone_names,
        skin_bind_pose=skin_bind_pose,
        init_render_local_to_world=setup.init_render_local_to_world,
        init_render_world_to_local=setup.init_render_world_to_local,
        init_render_rotation=setup.init_render_rotation, init_scale=setup.init_scale,
        volume_rest=constraints.rest_volumes(model.local_position, model.volume_vertices,
                                             setup.init_render_local_to_world),
    )


def _build(setup, spec, name, mode, root_names) -> ClothModel:
    params = getattr(spec, "parameters", None)
    n = setup.count

    # §B.2 import, §B.3 connection
    pos, normal, tangent, skin_bind_pose = virtual_mesh.import_bones(setup)
    parent = setup.parent_vertex
    if mode == "line":
        lines = virtual_mesh.connect_lines(parent)
        triangles = np.zeros((0, 3), dtype=np.int32)
    else:
        lines, triangles, _ = virtual_mesh.connect_mesh(name, mode, pos, parent, setup.child_vertices,
                                                        setup.root_vertices, setup.bone_names)
    _check_limit(name, "triangles", len(triangles), root_names)
    uv = virtual_mesh.spherical_uv(pos) if len(triangles) else np.zeros((n, 2))
    avg_dist, max_dist = virtual_mesh.vertex_distances(pos, lines, triangles)

    # §B.5 selection, §B.4 proxy conversion
    attribute = proxy.selection_attributes(name, setup, getattr(spec, "bone_attributes", None))
    nb_start, nb_count, nb_data, edges = proxy.adjacency(n, lines, triangles)
    _check_limit(name, "edges", len(edges), root_names)
    triangles, tri_normals = proxy.orient_triangles(pos, triangles)
    tri_tangents = proxy.triangle_tangents(pos, triangles, uv)
    vt_start, vt_count, vt_data, in_triangle = proxy.vertex_triangles(n, triangles)
    attribute[in_triangle] |= proxy.TRIANGLE
    normal, tangent, vt_flip = proxy.vertex_frames(tri_normals, tri_tangents, vt_start, vt_count, vt_data,
                                                   normal, tangent)
    center_fixed = proxy.center_fixed_list(attribute, nb_start, nb_count, nb_data)
    local_center = pos[center_fixed].mean(axis=0) if len(center_fixed) else np.zeros(3)
    child_start, child_count, child_data = proxy.children_csr(parent)
    bl_flags, bl_start, bl_count, bl_data = proxy.baselines(setup.root_vertices, attribute,
                                                            child_start, child_count, child_data)
    bind_rotation = np.empty((n, 4))
    v2t = np.empty((n, 4))
    proxy.vertex_rotations(normal, tangent, setup.component_rotation, np.array([0.0, 0.0, 0.0, 1.0]),
                           bind_rotation, v2t)
    bl_pos = np.zeros((n, 3))
    bl_rot = np.zeros((n, 4))
    bl_rot[:, 3] = 1.0
    proxy.baseline_pose(bl_data, parent, pos, normal, tangent, bl_pos, bl_rot, attribute, proxy.ZERO_DISTANCE)
    root_index = np.empty(n, dtype=np.int32)
    root_length = np.empty(n)
    proxy.root_index_and_length(parent, attribute, pos, proxy.MOVE, root_index, root_length)
    depth = proxy.depth_from_length(root_length)

    # §B.9 / §D.7 constraint data, switched by the parameters (§F)
    features, skipped = {}, {}
    features["lines"] = len(lines) > 0
    features["triangles"] = len(triangles) > 0
    d_start, d_count, d_target, d_rest = constraints.distance_links(
        attribute, parent, pos, nb_start, nb_count, nb_data, triangles, tri_normals, edges)
    _feature(features, skipped, "distance", len(d_target) > 0, "no edge touches a Move particle")
    _feature(features, skipped, "tether", bool((root_index >= 0).any()), "no Move particle has a root")
    use_restoration = bool(constraints.parameter(params, "angle_restoration.use"))
    use_limit = bool(constraints.parameter(params, "angle_limit.use"))
    _feature(features, skipped, "angle_restoration", use_restoration and len(bl_start) > 0,
             "angle_restoration.use is off" if not use_restoration else "no baselines")
    _feature(features, skipped, "angle_limit", use_limit and len(bl_start) > 0,
             "angle_limit.use is off" if not use_limit else "no baselines")
    _feature(features, skipped, "angle", features["angle_restoration"] or features["angle_limit"],
             "angle_restoration.use and angle_limit.use are off" if not (use_restoration or use_limit)
             else "no baselines")
    empty4 = np.zeros((0, 4), dtype=np.int32)
    bend = (empty4, np.zeros(0), np.zeros(0), empty4, np.zeros(0))
    if len(triangles) and constraints.wants_bending(params):
        bend = constraints.bending_and_volume(attribute, triangles, pos, setup.init_render_local_to_world)
        _feature(features, skipped, "bending", len(bend[0]) > 0, "no triangle pair below 120°")
        _feature(features, skipped, "volume", len(bend[3]) > 0, "no triangle pair between 90° and 179°")
    else:
        reason = "no triangles (line mode or no mesh)" if not len(triangles) else "triangle_bending.stiffness is 0"
        _feature(features, skipped, "bending", False, reason)
        _feature(features, skipped, "volume", False, reason)
    use_max = bool(constraints.parameter(params, "motion.use_max_distance"))
    use_back = bool(constraints.parameter(params, "motion.use_backstop")) and \
        float(constraints.parameter(params, "motion.backstop_radius")) > 0.0
    _feature(features, skipped, "motion", use_max or use_back,
             "motion.use_max_distance and motion.use_backstop are off")
    colliders = np.asarray(tuple(getattr(spec, "colliders", ()) or ()), dtype=np.int32).reshape(-1)
    collision_mode = str(getattr(spec, "collision_mode", "point") or "none")
    if collision_mode not in ("none", "point", "edge"):
        raise BuildError(name, f"collision_mode {collision_mode!r}: expected 'none', 'point' or 'edge'")
    for m in ("point", "edge"):
        why = ("collision_mode is " + collision_mode if collision_mode != m else
               "no colliders" if not len(colliders) else
               "no edges" if m == "edge" and not len(edges) else "")
        _feature(features, skipped, "collision_" + m, not why, why)
    built_mode = next((m for m in ("point", "edge") if features["collision_" + m]), "none")
    if built_mode == "none":
        colliders = np.zeros(0, dtype=np.int32)

    g = np.asarray(constraints.parameter(params, "gravity_direction"), dtype=np.float64)
    g_len = portable.norm(g)
    if not len(center_fixed):
        gravity_dir = np.array([0.0, -1.0, 0.0])  # §C.2: constant without a center
    else:  # the world gravity direction taken as a center-local vector (zero if too short)
        gravity_dir = g / g_len if g_len > 1e-8 else np.zeros(3)

    arrays = dict(
        attribute=attribute, parent=parent, root_index=root_index, root_length=root_length,
        child_start=child_start, child_count=child_count, child_data=child_data, depth=depth,
        local_position=pos, local_normal=normal, local_tangent=tangent, bind_rotation=bind_rotation,
        vertex_to_transform_rotation=v2t, skin_bind_pose=skin_bind_pose, vertex_uv=uv,
        baseline_local_position=bl_pos, baseline_local_rotation=bl_rot, baseline_flags=bl_flags,
        baseline_start=bl_start, baseline_count=bl_count, baseline_data=bl_data,
        center_fixed=center_fixed, local_center_position=local_center,
        edges=edges, lines=lines, triangles=triangles,
        neighbor_start=nb_start, neighbor_count=nb_count, neighbor_data=nb_data,
        vertex_triangle_start=vt_start, vertex_triangle_count=vt_count, vertex_triangle_data=vt_data,
        vertex_triangle_flip=vt_flip, triangle_uv=uv[triangles] if len(triangles) else np.zeros((0, 3, 2)),
        distance_start=d_start, distance_count=d_count, distance_target=d_target, distance_rest=d_rest,
        bend_vertices=bend[0], bend_rest_angle=bend[1], bend_sign=bend[2],
        volume_vertices=bend[3], volume_rest=bend[4], collider_index=colliders,
    )
    return ClothModel(
        name=name, connection_mode=mode, particle_count=n, transform_index=setup.transform_index,
        component_transform=setup.component_transform, bone_names=setup.bone_names,
        root_vertices=setup.root_vertices,
        collider_slot_capacity=int(math.ceil(len(colliders) / EXPANDED_COLLIDER_COUNT) * EXPANDED_COLLIDER_COUNT),
        collision_mode=built_mode,
        init_render_local_to_world=setup.init_render_local_to_world,
        init_render_world_to_local=setup.init_render_world_to_local,
        init_render_rotation=setup.init_render_rotation, init_scale=setup.init_scale,
        init_local_gravity_direction=gravity_dir,
        average_vertex_distance=avg_dist, max_vertex_distance=max_dist,
        aabb_min=pos.min(axis=0), aabb_max=pos.max(axis=0),
        curves=MappingProxyType(constraints.curve_tables(params)),
        features=MappingProxyType(features), skipped=MappingProxyType(skipped),
        topology_key=topology_hash(arrays, features),
        **arrays,
    )


def _feature(features, skipped, key, built, reason):
    features[key] = bool(built)
    if not built:
        skipped[key] = reason
