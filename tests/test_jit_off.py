"""With ``NUMBA_DISABLE_JIT=1`` every kernel runs as Python, so a stage can be stepped in a
debugger or measured by coverage: the tail showcase runs a few frames that way and gives the
compiled run's bits (the kernels use no intrinsic without a Python twin, ``kernels/trig.fma``)."""
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SNIPPET = """
import json, sys
import numba
import magica_py
result = magica_py.simulate("configs/tail_orbit.yaml", frames=4)
track = result.cloths["tail"]
print(json.dumps({"jit_off": bool(numba.config.DISABLE_JIT),
                  "positions": track.positions.tolist(), "rotations": track.rotations.tolist()}))
"""
# the character in quality mode: point collision against capsules (particles with and without
# a contact, at rest and moving), quality mode's end-of-step passes, collision last and display
CHARACTER_SNIPPET = """
import json
import numba
import magica_py
quality = ["cloths.hair.parameters.solver.mode=quality", "cloths.skirt.parameters.solver.mode=quality"]
result = magica_py.simulate("configs/character_walk.yaml", frames=6, overrides=quality)
print(json.dumps({"jit_off": bool(numba.config.DISABLE_JIT),
                  "positions": [result.cloths[c].positions.tolist() for c in ("hair", "skirt")],
                  "rotations": [result.cloths[c].rotations.tolist() for c in ("hair", "skirt")]}))
"""


def _run(disable_jit: bool, snippet: str = SNIPPET) -> dict:
    env = dict(os.environ)
    env.pop("NUMBA_DISABLE_JIT", None)
    if disable_jit:
        env["NUMBA_DISABLE_JIT"] = "1"
    # numpy's RuntimeWarnings (an overflow, a division by zero in a discarded branch) become
    # errors: with the JIT off the kernels' arithmetic on numpy scalars warns where compiled
    # code wraps or gives inf silently
    out = subprocess.run([sys.executable, "-W", "error::RuntimeWarning", "-c", snippet], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=1800)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_tail_orbit_runs_with_the_jit_off_and_gives_the_compiled_bits():
    off = _run(True)
    on = _run(False)
    assert off["jit_off"] and not on["jit_off"]
    positions_off, positions_on = np.array(off["positions"]), np.array(on["positions"])
    assert positions_off.shape == (4, 8, 3) and np.isfinite(positions_off).all()
    assert np.abs(np.diff(positions_off[:, -1], axis=0)).max() > 1e-4  # the tail moved
    assert positions_off.tobytes() == positions_on.tobytes()
    assert np.array(off["rotations"]).tobytes() == np.array(on["rotations"]).tobytes()


def test_character_in_quality_mode_runs_with_the_jit_off_and_gives_the_compiled_bits():
    """The branch-free kernels select between results, so a discarded branch must not divide
    by zero in Python either (a particle out of every collider's reach, one at rest)."""
    off = _run(True, CHARACTER_SNIPPET)
    on = _run(False, CHARACTER_SNIPPET)
    assert off["jit_off"] and not on["jit_off"]
    for a, b in zip(off["positions"], on["positions"]):
        a, b = np.array(a), np.array(b)
        assert a.shape[0] == 6 and np.isfinite(a).all()
        assert a.tobytes() == b.tobytes()
    for a, b in zip(off["rotations"], on["rotations"]):
        assert np.array(a).tobytes() == np.array(b).tobytes()


# a strand hanging at rest straight down: every edge is exactly along its rest direction, so the
# angle restoration takes its parallel path (its discarded turn divides by a zero length)
HANGING_SNIPPET = """
import json
import numba
import magica_py
SCENE = '''
version: 1
scene: {name: hanging, fps: 60, duration: 1.0, simulation_frequency: 90, gravity: [0, -9.81, 0]}
rigs:
  - name: strand
    bones:
      - {name: root, position: [0, 1.5, 0]}
    parts:
      - chain: {name: hair, parent: root, bones: 6, length: 0.5, direction: [0, -1, 0]}
cloths:
  - {name: hair, type: bone_cloth, root_bones: [hair_0], connection: line, collision_mode: none}
'''
track = magica_py.simulate(SCENE, frames=3).cloths["hair"]
print(json.dumps({"jit_off": bool(numba.config.DISABLE_JIT),
                  "positions": track.positions.tolist(), "rotations": track.rotations.tolist()}))
"""


def test_a_strand_hanging_at_rest_runs_with_the_jit_off_and_gives_the_compiled_bits():
    off = _run(True, HANGING_SNIPPET)
    on = _run(False, HANGING_SNIPPET)
    assert off["jit_off"] and not on["jit_off"]
    positions = np.array(off["positions"])
    assert positions.shape == (3, 6, 3) and np.isfinite(positions).all()
    assert np.array_equal(positions[:, :, [0, 2]], np.zeros((3, 6, 2)))   # it stays in its vertical line
    assert positions.tobytes() == np.array(on["positions"]).tobytes()
    assert np.array(off["rotations"]).tobytes() == np.array(on["rotations"]).tobytes()


# frame by frame, long enough to reach what a few frames do not: the C.4 movement smoothing
# (every scene's default 0.4: ``0.6 ** 3`` rounds differently in Python than compiled, which
# showed first at frame 20 of the character and 88 of the tail), zero-length bones (a zero
# divisor, an exception in Python), a 100 m teleport and a scale of 100
PARITY_SCENES = (("configs/tail_orbit.yaml", 95), ("configs/hard/zero_length_bones.yaml", 10),
                 ("configs/hard/scale_100.yaml", 25), ("configs/hard/teleport_100m_off.yaml", 35),
                 ("configs/character_walk.yaml", 22))
PARITY_SNIPPET = """
import hashlib, json
import numba
import numpy as np
from magica_py.config import load_scene
from magica_py.runtime.player import Player
from magica_py.solver.system import ClothSystem

np.seterr(all="ignore")   # as the interpreted first run does (magica_py/first_run.py)
frames = {}
for path, count in %r:
    scene = load_scene(path)
    h = scene.hierarchy
    player = Player.for_scene(scene)
    system = ClothSystem(h, scene.cloths, scene.colliders, scene.settings).attach(player)
    hashes = []
    for _ in range(count):
        player.step()
        digest = hashlib.sha256()
        for a in (system.particles.position, h.local_position, h.local_rotation, h.world_position,
                  h.world_rotation):
            digest.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
        hashes.append(digest.hexdigest()[:16])
    frames[path] = hashes
print(json.dumps({"jit_off": bool(numba.config.DISABLE_JIT), "frames": frames}))
""" % (PARITY_SCENES,)


def test_every_frame_of_hard_scenes_has_the_compiled_bits_with_the_jit_off():
    """The interpreted first run (``magica_py/first_run.py``) must record what the compiled
    runs after it record: particles and every bone's local and world pose, frame by frame."""
    off = _run(True, PARITY_SNIPPET)
    on = _run(False, PARITY_SNIPPET)
    assert off["jit_off"] and not on["jit_off"]
    for path, count in PARITY_SCENES:
        a, b = off["frames"][path], on["frames"][path]
        assert len(a) == len(b) == count
        first = next((k for k, (x, y) in enumerate(zip(a, b)) if x != y), None)
        assert first is None, f"{path}: the jit-off run differs from frame {first} on"


# host-side lines (plain Python on arrays' summaries, never in a kernel) allowed a math.sqrt
# (build.virtual_mesh's link statistics, solver.parameters' constant, team_time's SimulationPower)
HOST_SQRT = ("float(math.sqrt(", "SQRT3 = math.sqrt(", "math.sqrt(r) if r > 1.0 else r")


def test_kernel_sources_take_no_integer_power_and_no_math_sqrt():
    """What made the interpreted run differ from the compiled one, kept out of the kernel
    modules: ``x ** n`` with an integer n (Python's pow rounds otherwise than numba's products)
    and ``math.sqrt`` (a Python float, whose division by zero raises where compiled code gives
    inf; ``np.sqrt`` compiles to the same instruction). Comments and strings are skipped."""
    import io
    import re
    import tokenize

    found = []
    for folder in ("kernels", "solver", "build", "scene", "wind", "runtime"):
        for path in sorted((ROOT / "magica_py" / folder).rglob("*.py")):
            text = path.read_text()
            if "@kernel" not in text:
                continue
            tokens = [t for t in tokenize.generate_tokens(io.StringIO(text).readline)
                      if t.type not in (tokenize.COMMENT, tokenize.STRING)]
            for a, b in zip(tokens, tokens[1:]):
                if a.string == "**" and b.type == tokenize.NUMBER and re.fullmatch(r"\d+", b.string):
                    found.append(f"{path.relative_to(ROOT)}:{a.start[0]}: ** {b.string}")
            for number, line in enumerate(text.splitlines(), 1):
                code = line.split("#", 1)[0]
                if "math.sqrt(" in code and not any(h in code for h in HOST_SQRT):
                    found.append(f"{path.relative_to(ROOT)}:{number}: math.sqrt")
    assert not found, found


COMPILE_SNIPPET = """
import json
from numba.core import event
import magica_py

compiled = set()
signatures = []   # (module.name, argument types) of every compile of a package function


class Names(event.Listener):
    def on_start(self, ev):
        fn = ev.data["dispatcher"].py_func
        compiled.add(fn.__name__)
        if str(fn.__module__).startswith("magica_py"):
            signatures.append((f"{fn.__module__}.{fn.__qualname__}", [str(a) for a in ev.data["args"]]))

    def on_end(self, ev):
        pass


# first what a first run's helper process and the system's process compile before the frame
# kernel (solver/compile_helper.py), with another system of the same scene's arrays
from magica_py.config import load_scene
from magica_py.solver.frame import compile_end_stages, compile_late_stages, compile_step_stages
from magica_py.solver.system import ClothSystem

scene = load_scene("configs/tail_orbit.yaml")
system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings)
s = system.stages
with event.install_listener("numba:compile", Names()):
    F = system._frame_arrays()
    compile_step_stages(F, system._frame_values, None, s.angle, s.bending, s.point_collision, s.edge_collision,
                        s.motion, s.quality, s.wind, s.colliders)
    compile_late_stages(F, system._frame_values, s.colliders)
    compile_end_stages(F, system._frame_values, system._save_area, s.quality, s.lines, s.triangles, s.colliders)
before_frames = set(compiled)
compiled.clear()
with event.install_listener("numba:compile", Names()):
    result = magica_py.simulate("configs/tail_orbit.yaml", frames=4)
from magica_py.solver.frame import simulate_frame
# the size of each function's final LLVM module (its own code and every callee linked into it)
ir = {fn.__name__: len(fn.inspect_llvm(fn.signatures[0]))
      for fn in (compile_step_stages, compile_late_stages, compile_end_stages, simulate_frame)}
print(json.dumps({"positions": result.cloths["tail"].positions.tolist(), "compiled": sorted(compiled | before_frames),
                  "before_frames": sorted(before_frames), "in_frames": sorted(compiled), "signatures": signatures,
                  "ir": ir}))
"""
# the optional stages tail_orbit (line mode, angle restoration, no collider, no motion
# constraint, faithful mode, no wind: ``ClothSystem.stages`` has angle and lines only) does not
# use: their lane-form drivers are never compiled (a None switch prunes the call, frame.py)
UNUSED_BY_TAIL_ORBIT = ("bending_block", "apply_accumulated_block", "point_collision_block", "edge_collision_block",
                        "motion_block", "quality_end_of_step_block", "drift_begin_block", "drift_end_block",
                        "ftl_collision_lane", "edge_projection_lane", "collision_last_lane", "build_reset_lane",
                        "display_constraints_block", "record_display_state_block", "display_interpolated",
                        "triangle_rotations_block", "wind_block", "collider_step_block", "collider_end_step_block",
                        "collider_frame_block", "collider_end_frame_block")


@pytest.fixture(scope="module")
def bounds_checked_tail(tmp_path_factory):
    """The tail's first frames compiled from an empty cache with ``NUMBA_BOUNDSCHECK=1``, in a
    subprocess (``COMPILE_SNIPPET``): its positions and what numba compiled."""
    # no compile helper (solver/compile_helper.py): every kernel compiles in this process, where
    # the compile events see it; the stages the tail uses, not every stage (tests/conftest.py)
    cache = tmp_path_factory.mktemp("numba-cache")
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", NUMBA_CACHE_DIR=str(cache), MAGICA_COMPILE_HELPER="0",
               MAGICA_STAGES="used")
    env.pop("NUMBA_DISABLE_JIT", None)
    out = subprocess.run([sys.executable, "-c", COMPILE_SNIPPET], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=3600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_tail_orbit_runs_bounds_checked_and_compiles_only_the_stages_it_uses(bounds_checked_tail):
    """``NUMBA_BOUNDSCHECK=1`` compiles every index with a check (an out-of-range index raises
    IndexError instead of reading memory); the frame path has no access outside its arrays.
    The run has a cache of its own (checked and unchecked code must not share cache entries),
    so every kernel it needs is compiled here: numba's compile events name them, and the
    optional stages the scene does not use are not among them (``frame.StageSwitches``)."""
    checked = bounds_checked_tail
    compiled = set(checked["compiled"])
    assert {"simulate_frame", "predict_block", "distance_block", "angle_block",
            "line_rotations_block"} <= compiled
    assert not compiled & set(UNUSED_BY_TAIL_ORBIT), sorted(compiled & set(UNUSED_BY_TAIL_ORBIT))
    # the stages compiled ahead of the frame kernel (a first run's helper compiles the step's
    # stages and then the last of the begin and close of frame into the cache, the system's
    # process the end-of-frame stages) are the ones the frame kernel calls: it compiles none of
    # them again with other argument types
    late = {"frame_counts", "_frame_close", "team_time_begin_step_team", "team_time_end_frame"}
    ahead = {name for name in checked["before_frames"] if name.endswith(("_block", "_lane", "_lanes")) or name in late}
    assert {"predict_block", "distance_block", "angle_block", "end_step_block", "line_rotations_block",
            "transform_block", "reset_or_shift_block", "center_and_inertia_lane"} | late <= ahead, \
        sorted(ahead)
    assert not ahead & set(checked["in_frames"]), sorted(ahead & set(checked["in_frames"]))
    assert np.array(checked["positions"]).tobytes() == np.array(_run(False)["positions"]).tobytes()


def test_the_compile_wrappers_keep_none_of_the_stages_code(bounds_checked_tail):
    """The ``frame.compile_*`` functions only type the stages (``frame.typed_only``): numba
    compiles every stage they name into the cache, and LLVM drops the never-taken calls before
    it optimises and emits the wrapper's module, so the wrapper does not carry every stage's
    code once more. Each wrapper's module is a small fraction of the frame kernel's (with a
    condition LLVM cannot fold, ``n == 123456789``, the step wrapper's was 44 % of it in this
    bounds-checked build; with ``typed_only`` about 3 %)."""
    ir = bounds_checked_tail["ir"]
    for name in ("compile_step_stages", "compile_late_stages", "compile_end_stages"):
        assert ir[name] < 0.1 * ir["simulate_frame"], ir


def _repeated_signatures():
    """``benchmarks/compile_profile.py``'s census of functions compiled more than once."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("compile_profile", ROOT / "benchmarks" / "compile_profile.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.repeated_signatures


def test_repeated_signatures_names_a_function_compiled_twice():
    repeated_signatures = _repeated_signatures()
    signatures = [("m.f", ["int64"]), ("m.f", ["int32"]), ("m.g", ["int64"]), ("m.g", ["int64"])]
    assert repeated_signatures(signatures) == {"m.f": [("int32",), ("int64",)]}


def test_tail_orbit_compiles_each_package_function_for_one_signature(bounds_checked_tail):
    """A constant argument (``Literal``) or an int32 index where another call passes an int64
    makes numba compile a function again (docs/tech-notes.md §7): every package function the
    tail's first frames compile (the solver's stages and helpers, the animation, the
    propagation) has one signature."""
    assert bounds_checked_tail["signatures"], "no compile seen: the run used a warm cache"
    assert _repeated_signatures()(bounds_checked_tail["signatures"]) == {}
