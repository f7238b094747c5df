"""Import timings on the shared test files: ``python -m magica_py.io.bench [data_dir]``.

Best of 3 per file (the first call also pays numba compilation of the clip sampler).
"""
from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
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
