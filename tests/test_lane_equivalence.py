"""The lane form against the per-team solver it replaced, bit for bit (CI's share of
``benchmarks/port_check.py``): a few small scenes and variants run frame by frame through
both solvers (``tests/reference_solver``, frozen) and every team's display positions and the
hierarchy's local and world poses compared exactly after every frame (``port_check.check``).

The full sweep (every scene and variant, 120 frames) is ``python benchmarks/port_check.py``."""
from __future__ import annotations

import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
FRAMES = 20


def _port_check():
    spec = importlib.util.spec_from_file_location("port_check", ROOT / "benchmarks" / "port_check.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


port_check = _port_check()


# (scene, variant, threads): tail_orbit, a line-mode tail (the faithful core stages, a block of
# one lane). Each case compiles the reference solver's frame for its stages (45-90 s with a cold
# numba cache and NUMBA_BOUNDSCHECK=1, against the CI's 15 minutes), so CI keeps this one;
# blocks of several lanes against the reference are ``tests/test_lane_masking.py``, the crowd's
# and every showcase's faithful bits the golden hashes (``tests/test_quality_faithful_unchanged.py``),
# the parallel kernel against the serial one ``tests/test_solver_frame.py``. The other scenes and
# variants (the crowd on two threads; character_walk in quality mode with capsules, bending and
# triangles; edge, motion, loop_mesh, wind, ...) are ``python benchmarks/port_check.py`` (all
# identical over 40-100 frames on 1 and 2 threads, docs/BENCHMARKS.md, session 10).
CASES = [
    ("tail_orbit", "faithful", 1),
]


@pytest.mark.parametrize("scene, variant, threads", CASES)
def test_the_lane_form_gives_the_reference_solvers_bits(scene, variant, threads):
    path = ROOT / "configs" / f"{scene}.yaml"
    verdict = port_check.check(path, variant, FRAMES, threads)
    assert verdict == f"identical over {FRAMES} frames", verdict
