"""The lane-form solver against the per-team reference, bit for bit, frame by frame.

    python benchmarks/port_check.py [--frames 120] [--scenes NAME ...] [--variants faithful quality ...]
                                    [--threads 1 2] [--list]

For every scene (``configs/*.yaml`` and ``configs/hard/*.yaml``; those that need
``../shared/data`` are skipped when it is absent) and every variant (``faithful``: the file as
it is; ``quality``: every cloth with ``solver.mode: quality``; ``consistent``: every cloth with
``solver.rate_mode: frequency_consistent``; ``moving_wind``: every cloth with
``wind.moving_wind: 1``; ``quality_iterations``, ``quality_edge``: quality mode with the
``iterations`` inextensibility option, or with collision_mode edge), the scene is loaded
twice, the package's ``ClothSystem`` attached to one player and ``tests/reference_solver``'s per-team
``ClothSystem`` (the solver before the lane form, frozen) to the other, and both run frame by
frame. After each frame the display positions of every team and the hierarchy's local and
world poses are compared bit for bit; the first difference is reported with the frame, the
team and the largest deviation. Exit 1 when any pair differs.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

# quality mode's contact speed limit (solver/contact_speed.py) came after the per-team solver was
# frozen: the quality variants compare everything else with it off (tests/test_quality_contact_speed.py
# pins the limit itself)
NO_CONTACT_LIMIT = "parameters.solver.contact_speed_limit=false"
VARIANTS = {
    "faithful": [],
    "quality": ["parameters.solver.mode=quality", NO_CONTACT_LIMIT],
    "consistent": ["parameters.solver.rate_mode=frequency_consistent"],
    # stages no showcase scene uses: edge collision (D.8 edge mode), the motion constraint (D.9)
    "edge": ["collision_mode=edge"],
    "motion": ["parameters.motion.use_max_distance=true", "parameters.motion.use_backstop=true"],
    # the angle limit with D.2's rest shape blended halfway to the animated pose, or kept as
    # the animated pose: the limit then reads D.1's animated rotations of the moving particles
    # (step.moving_rotation_read)
    "pose_blend": ["parameters.animation_pose_ratio=0.5", "parameters.angle_limit.use=true"],
    "pose_kept": ["parameters.animation_pose_ratio=1.0", "parameters.angle_limit.use=true"],
    # D.10 without friction, particle speed limit or centrifugal term (the light scene's end of
    # step, compiled without their paths: step.end_step_block)
    "no_extras": ["parameters.collider_collision.friction=0", "parameters.inertia.particle_speed_limit=off",
                  "parameters.inertia.centrifugal_acceleration=0"],
    # every cloth a closed mesh: a fan of strands (the character's hair) then has volume pairs (D.7)
    "loop_mesh": ["connection=sequential_loop_mesh"],
    # the wind a cloth makes from its own movement (wind.moving_wind)
    "moving_wind": ["parameters.wind.moving_wind=1.0"],
    # quality mode with the brute-force inextensibility option (D.4 passes, no drift)
    "quality_iterations": ["parameters.solver.mode=quality", "parameters.solver.inextensibility=iterations",
                           NO_CONTACT_LIMIT],
    # quality mode after D.8 edge mode (collision last follows edge collision)
    "quality_edge": ["parameters.solver.mode=quality", "collision_mode=edge", NO_CONTACT_LIMIT],
}


def scene_paths(names):
    paths = sorted((ROOT / "configs").glob("*.yaml")) + sorted((ROOT / "configs" / "hard").glob("*.yaml"))
    if names:
        paths = [p for p in paths if p.stem in names or str(p.relative_to(ROOT / "configs"))[:-5] in names]
    return paths


def load(path, variant, frames):
    from magica_py.config import load_scene

    scene = load_scene(path)
    extra = []
    if VARIANTS[variant]:
        for i in range(len(_cloth_entries(path))):
            extra += [f"cloths[{i}].{o}" for o in VARIANTS[variant]]
    return load_scene(path, extra) if extra else scene


def _cloth_entries(path):
    import yaml

    doc = yaml.safe_load(pathlib.Path(path).read_text())
    return doc.get("cloths", []) or []


def pose_of(h):
    return (h.local_position, h.local_rotation, h.world_position, h.world_rotation)


def check(path, variant, frames, threads):
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem
    from reference_solver.solver.system import ClothSystem as ReferenceSystem

    try:
        a_scene = load(path, variant, frames)
        b_scene = load(path, variant, frames)
    except Exception as exc:  # a variant a scene refuses (e.g. data missing)
        return f"skipped ({type(exc).__name__}: {str(exc).splitlines()[0][:100]})"
    n = frames or a_scene.settings.frames or 120
    a_player = Player.for_scene(a_scene)
    b_player = Player.for_scene(b_scene)
    parallel = threads > 1
    a = ClothSystem(a_scene.hierarchy, a_scene.cloths, a_scene.colliders, a_scene.settings,
                    parallel=parallel, wind=getattr(a_scene, "wind", ())).attach(a_player)
    b = ReferenceSystem(b_scene.hierarchy, b_scene.cloths, b_scene.colliders, b_scene.settings,
                        parallel=parallel, wind=getattr(b_scene, "wind", ())).attach(b_player)
    for frame in range(n):
        a_player.step()
        b_player.step()
        for t in b.live_teams:
            pa = a.positions(t)
            pb = b.positions(t)
            if not np.array_equal(pa, pb, equal_nan=True):
                d = np.nanmax(np.abs(pa - pb)) if pa.shape == pb.shape else float("nan")
                return f"DIFFERS at frame {frame}, team {t} ({b.team_names[t]}): positions, max |d| {d:.3e}"
        for name, x, y in zip(("local_position", "local_rotation", "world_position", "world_rotation"),
                              pose_of(a_scene.hierarchy), pose_of(b_scene.hierarchy)):
            if not np.array_equal(x, y, equal_nan=True):
                d = np.nanmax(np.abs(x - y))
                return f"DIFFERS at frame {frame}: hierarchy {name}, max |d| {d:.3e}"
    return f"identical over {n} frames"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--scenes", nargs="*", default=[])
    ap.add_argument("--variants", nargs="+", default=["faithful", "quality"], choices=list(VARIANTS))
    ap.add_argument("--threads", type=int, nargs="+", default=[1])
    ap.add_argument("--list", action="store_true")
    args = ap.parse_args(argv)
    paths = scene_paths(args.scenes)
    if args.list:
        print("\n".join(str(p.relative_to(ROOT)) for p in paths))
        return 0
    bad = 0
    for path in paths:
        for variant in args.variants:
            for threads in args.threads:
                t0 = time.perf_counter()
                verdict = check(path, variant, args.frames, threads)
                bad += verdict.startswith("DIFFERS")
                print(f"{str(path.relative_to(ROOT / 'configs')):38s} {variant:10s} {threads}t  {verdict}"
                      f"  ({time.perf_counter() - t0:.1f} s)", flush=True)
    print("all identical" if not bad else f"{bad} differ")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
