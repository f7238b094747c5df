"""Import timings and the VRM mapping check.

* ``python -m magica_py.io.bench [data_dir]``: import timings on the shared test files, best
  of 3 per file (the first call also pays numba compilation of the clip sampler);
* ``python -m magica_py.io.bench mapping``: one horizontal segment under gravity, starting
  from rest, simulated by the real solver with the mapped parameters and by a numpy UniVRM
  segment; prints the final sag angles and the RMS difference over the first second
  (docs/import.md §3). Needs the solver (first run compiles it: minutes).
"""
from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path


def vrm_segment_angles(stiffness, gravity_power, drag, length, frames, fps=60.0):
    """Sag angle (degrees) per frame of a UniVRM segment whose rest direction is +X."""
    import math

    import numpy as np
    dt = 1.0 / fps
    rest = np.array([1.0, 0.0, 0.0])
    cur = prev = rest * length
    out = []
    for _ in range(frames):
        nxt = cur + (cur - prev) * (1 - drag) + rest * stiffness * dt + np.array([0.0, -1.0, 0.0]) * gravity_power * dt
        nxt = nxt / np.linalg.norm(nxt) * length
        prev, cur = cur, nxt
        out.append(math.degrees(math.atan2(-cur[1], cur[0])))
    return np.array(out)


def mapping_check(cases=((2.0, 0.2, 0.4, 0.1), (1.0, 0.2, 0.1, 0.1), (1.0, 0.1, 0.4, 0.3), (4.0, 0.5, 0.4, 0.05))) -> int:
    import math

    import numpy as np

    from magica_py.io.mapping import map_spring_parameters
    from magica_py.params import resolve_parameters
    from magica_py.scene.hierarchy import BoneSpec, TransformHierarchy
    from magica_py.scene.scene import ClothSpec
    from magica_py.solver.system import ClothSystem

    for stiffness, power, drag, length in cases:
        h = TransformHierarchy([BoneSpec("body"), BoneSpec("root", "body", (0, 1, 0)),
                                BoneSpec("tip", "root", (length, 0, 0))])
        mapped = map_spring_parameters(stiffness, power, (0, -1, 0), drag, 0.02, length)
        spec = ClothSpec(name="segment", root_bones=(h.index("root"),), component=h.index("body"),
                         connection_mode="line", parameters=resolve_parameters(None, mapped.parameters, "mapped"),
                         collision_mode="none")
        system = ClothSystem(h, [spec])
        restored = system.restored_bones()
        ours = []
        for _ in range(600):
            h.restore_rest_pose(restored)
            h.propagate()
            system.step_frame(1.0 / 60.0)
            d = h.world_position[h.index("tip")] - h.world_position[h.index("root")]
            ours.append(math.degrees(math.atan2(-d[1], d[0])))
        ours = np.array(ours)
        ref = vrm_segment_angles(stiffness, power, drag, length, 600)
        p = mapped.parameters
        print(f"stiffness {stiffness:g} gravityPower {power:g} drag {drag:g} L {length:g} m -> gravity {p['gravity']:.2f} "
              f"damping {p['damping']['value']:.3f} restoration {p['angle_restoration.stiffness']['value']:.3f} "
              f"attenuation {p['angle_restoration.velocity_attenuation']:.3f} (mismatch {mapped.mismatch:.3f}): "
              f"final sag {ours[-1]:.2f} vs VRM {ref[-1]:.2f} deg, RMS first second "
              f"{np.sqrt(np.mean((ours[:60] - ref[:60]) ** 2)):.2f} deg")
    return 0


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["mapping"]:
        return mapping_check()
    data = Path(argv[0]) if argv else Path(__file__).resolve().parents[2].parent / "shared" / "data"
    from magica_py.io import ClipDriver, load_bvh, load_gltf, load_vrm, retarget
    from magica_py.scene.hierarchy import TransformHierarchy

    def best(label, fn, n=3):
        times = []
        for _ in range(n):
            start = time.perf_counter()
            result = fn()
            times.append(time.perf_counter() - start)
        print(f"{label}: {min(times) * 1e3:.1f} ms")
        return result

    warnings.simplefilter("ignore")
    best("load_gltf Fox.glb", lambda: load_gltf(data / "gltf" / "Fox.glb", unit_scale=0.01))
    best("load_gltf wuson.glb", lambda: load_gltf(data / "gltf" / "wuson.glb"))
    avatar = best("load_vrm Godette_vrm_v4.vrm", lambda: load_vrm(data / "vrm" / "Godette_vrm_v4.vrm"))
    bvh = best("load_bvh cmu_01_01.bvh", lambda: load_bvh(data / "bvh" / "cmu_01_01.bvh"))
    clip = best("retarget cmu_01_01 -> Godette", lambda: retarget(bvh.clip, bvh.bones, avatar.bones,
                                                                  target_map=avatar.humanoid, source_rest=0))
    h = TransformHierarchy(avatar.bones)
    driver = ClipDriver(clip, h)
    driver.apply(h, 0.0)
    frames = 10000
    start = time.perf_counter()
    for k in range(frames):
        driver.apply(h, k / 60.0)
    per = (time.perf_counter() - start) / frames
    print(f"ClipDriver.apply ({len(driver.track_node)} tracks, {len(driver.key_time)} keys): {per * 1e6:.1f} us/frame")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
