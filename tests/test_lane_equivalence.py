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


def _swinging_tails(tmp_path):
    """tail_orbit as four instances in one block (phases jittered) swinging about the vertical
    with a 30-degree angle limit: in many iterations some lanes of the block violate the limit
    and others do not."""
    text = (ROOT / "configs" / "tail_orbit.yaml").read_text()
    edits = [
        ("curl: 5}\n", "curl: 5}\n    instances: {count: 4, spacing: [3.0, 0, 0], phase_jitter: 1.0}\n"),
        ("orbit: {center: [0, 1, 0], radius: 0.5, period: 2.0, axis: [0, 1, 0], face_path: true}",
         "oscillate: {property: rotation, axis: [0, 1, 0], amplitude: 80, frequency: 1.3, phase: 0}"),
        ("parameters: {gravity: 2.0}", "parameters: {gravity: 2.0, angle_limit: {use: true, limit_angle: 30}}"),
    ]
    for old, new in edits:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / "swinging_tails.yaml"
    path.write_text(text)
    return path


def test_lanes_of_one_block_that_violate_the_angle_limit_while_others_do_not_give_the_reference_bits(tmp_path):
    """The angle stage solves a block's lanes without the limit's violation path and then the
    lanes that met a violation again on the full path (constraints/angle.py); a block where
    only some lanes violate in an iteration is where a mistake in that split would show."""
    import numpy as np

    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver import blocks as bk
    from magica_py.solver import state as st
    from magica_py.solver.system import ClothSystem

    path = _swinging_tails(tmp_path)
    scene = load_scene(path)
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    T = system.tables
    assert [int(T.BI[b, bk.BI_LANES_USED]) for b in T.blocks] == [4]
    mixed = 0
    for _ in range(FRAMES):
        player.step()
        flagged = T.PS[:, st.ANGLE_RARE:st.ANGLE_RARE + 4] != 0.0   # the last iteration's flags
        mixed += int(np.sum(flagged.any(axis=1) & ~flagged.all(axis=1)))
    assert mixed > 0
    verdict = port_check.check(path, "faithful", FRAMES, 1)
    assert verdict == f"identical over {FRAMES} frames", verdict


@pytest.mark.parametrize("variant", ["pose_blend", "pose_kept", "motion"])
def test_the_stages_that_read_the_moving_particles_animated_rotations_give_the_reference_bits(tmp_path, variant):
    """D.1 computes a moving particle's animated rotation at each step only where a stage reads
    it (``step.moving_rotation_read``): the angle limit after D.2 blended the rest shape towards
    the animated pose (ratio 0.5) or kept it (1.0), and the motion constraint. Four swinging
    tails with a 30-degree limit, so the limit acts on the rotations it reads."""
    path = _swinging_tails(tmp_path)
    verdict = port_check.check(path, variant, FRAMES, 1)
    assert verdict == f"identical over {FRAMES} frames", verdict


def test_the_end_of_step_without_friction_speed_limit_or_centrifugal_term_gives_the_reference_bits(tmp_path):
    """D.10 of a block with none of its optional terms runs a lane loop compiled without them
    (``step.end_step_block``'s ``extras``); every showcase has a speed limit, so the four
    swinging tails run here with friction 0, no speed limit and no centrifugal term."""
    path = _swinging_tails(tmp_path)
    verdict = port_check.check(path, "no_extras", FRAMES, 1)
    assert verdict == f"identical over {FRAMES} frames", verdict
