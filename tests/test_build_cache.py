"""ModelCache: instanced rigs reuse one build and get exactly what a fresh build gives."""
from __future__ import annotations

import numpy as np

from magica_py.build import ModelCache, build_cloth
from magica_py.params import resolve_parameters
from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
from test_build_rigs import SQUARE, Spec


def crowd(count, turn=True):
    bones = []
    s = np.sqrt(0.5)
    for c in range(count):
        rot = (0.0, s, 0.0, s) if (turn and c % 2) else (0.0, 0.0, 0.0, 1.0)
        bones.append(BoneSpec(f"hips{c}", None, (1.7 * c, 1.0, -0.3 * c), rot))
        for k, p in enumerate(SQUARE):
            parent = f"hips{c}"
            for b in range(3):
                bones.append(BoneSpec(f"c{c}s{k}_{b}", parent, p if b == 0 else (0.0, -0.1, 0.0)))
                parent = f"c{c}s{k}_{b}"
    h = TransformHierarchy(bones)
    # every character has its own collider: same topology, different collider index
    return h, [Spec(f"skirt{c}", tuple(h.index(f"c{c}s{k}_0") for k in range(4)), "sequential_loop_mesh",
                    parameters=resolve_parameters(None, {}), colliders=(c,)) for c in range(count)]


def test_cached_instances_equal_fresh_builds_array_for_array():
    h, specs = crowd(4)
    cache = ModelCache()
    cached = [build_cloth(h, s, cache) for s in specs]
    assert (cache.misses, cache.hits) == (1, 3)
    for spec, m in zip(specs, cached):
        fresh = build_cloth(h, spec, cache=None)
        assert m.name == fresh.name and m.bone_names == fresh.bone_names
        assert m.topology_key == fresh.topology_key
        for name, value in vars(fresh).items():
            if isinstance(value, np.ndarray):
                assert value.tobytes() == getattr(m, name).tobytes(), (spec.name, name)
                assert not getattr(m, name).flags.writeable
    # instances really differ where they should
    assert cached[0].transform_index[0] != cached[1].transform_index[0]
    assert not np.array_equal(cached[0].init_render_rotation, cached[1].init_render_rotation)
    assert [m.collider_index.tolist() for m in cached] == [[0], [1], [2], [3]]


def test_cache_misses_when_parameters_or_attributes_differ():
    h, specs = crowd(3, turn=False)
    cache = ModelCache()
    build_cloth(h, specs[0], cache)
    stiff = Spec(specs[1].name, specs[1].root_bones, specs[1].connection_mode, colliders=(1,),
                 parameters=resolve_parameters(None, {"triangle_bending": {"stiffness": 0.0}}))
    m = build_cloth(h, stiff, cache)
    assert len(m.bend_vertices) == 0
    pinned = Spec(specs[2].name, specs[2].root_bones, specs[2].connection_mode, parameters=specs[2].parameters,
                  colliders=(2,), bone_attributes={h.index("c2s0_1"): "fixed"})
    m = build_cloth(h, pinned, cache)
    assert (cache.misses, cache.hits) == (3, 0)
    assert m.attribute[list(m.bone_names).index("c2s0_1")] & 0x03 == 0x01  # fixed, not move


def test_default_cache_is_transparent_and_bounded():
    from magica_py.build import DEFAULT_CACHE, ModelCache as MC

    h, specs = crowd(3)
    before = DEFAULT_CACHE.hits
    models = [build_cloth(h, s) for s in specs]
    assert DEFAULT_CACHE.hits - before >= 2
    assert [m.name for m in models] == ["skirt0", "skirt1", "skirt2"]
    small = MC(max_entries=1)
    build_cloth(h, specs[0], small)
    other = Spec("tail", specs[0].root_bones, "line", parameters=specs[0].parameters, colliders=(0,))
    build_cloth(h, other, small)
    assert len(small.models) == 1 and small.misses == 2
