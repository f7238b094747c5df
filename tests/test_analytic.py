"""Analytic and invariant checks of the whole solver path (issue 6 part 3).

* the pendulum period against 2 pi sqrt(L/g) (with the finite-amplitude correction) at
  several simulation frequencies: the error must shrink as the step shrinks;
* the hanging chain with every restoring term off: straight down, lengths as measured;
* rigid-body invariance: a cloth under pure rotation of its root keeps its shape;
* determinism across processes: a second Python process reproduces the positions bit for bit.
"""
from __future__ import annotations

import hashlib
import math
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from magica_py.bench.variants import Variant, run_variant
from solver_scenes import pendulum_yaml

THETA0 = math.radians(3.0)      # small: the amplitude decays (docs/solver.md Appendix 4), the correction stays tiny
LENGTH = 1.0
G = 9.81


def scene_file(tmp_path, name, text):
    path = tmp_path / f"{name}.yaml"
    path.write_text(textwrap.dedent(text))
    return str(path)


def pendulum_scene(tmp_path, name="pendulum"):
    return scene_file(tmp_path, name, pendulum_yaml(THETA0, fps=120, duration=6.0, length=LENGTH, gravity=G,
                                                    solver="rate_mode: frequency_consistent", name=name))


def measured_period(times, x):
    """Mean period from the linearly interpolated zero crossings of x(t)."""
    s = np.sign(x)
    idx = np.nonzero(s[:-1] * s[1:] < 0)[0]
    crossings = times[idx] - x[idx] * (times[idx + 1] - times[idx]) / (x[idx + 1] - x[idx])
    assert crossings.shape[0] >= 6, "the pendulum must swing several times"
    return 2.0 * float(np.mean(np.diff(crossings)))


def exact_period():
    return 2 * math.pi * math.sqrt(LENGTH / G) * (1 + THETA0 ** 2 / 16 + 11 * THETA0 ** 4 / 3072)


@pytest.fixture(scope="module")
def pendulum_errors(tmp_path_factory):
    path = pendulum_scene(tmp_path_factory.mktemp("pendulum"))
    errors = {}
    for f in (30, 60, 90, 180, 360):
        run = run_variant(Variant(f"pendulum@{f}", path, frequency=f))
        x = run.positions[:, 1, 0] - run.positions[:, 0, 0]
        errors[f] = abs(measured_period(run.times, x) / exact_period() - 1.0)
    return errors


def test_pendulum_period_within_two_percent_at_90_hz(pendulum_errors):
    assert pendulum_errors[90] < 0.02


def test_pendulum_period_error_shrinks_with_the_step(pendulum_errors):
    from magica_py.bench.reference import fit_order

    e = pendulum_errors
    # measured: 1.9e-2, 2.0e-3, 6.3e-4, 1.0e-4, 1.3e-5 (frequency-consistent mode, 3 degrees)
    assert e[360] < e[180] < e[90] < e[60] < e[30], e
    assert e[360] < 1e-4, e
    order, _ = fit_order(list(e), list(e.values()))
    assert order > 1.5, (order, e)


def test_hanging_chain_with_restoring_terms_off_hangs_straight_down(tmp_path):
    path = scene_file(tmp_path, "hanging", """
        version: 1
        scene: {name: hanging, fps: 60, duration: 8.0}
        rigs:
          - name: r
            bones: [{name: anchor, position: [0, 2, 0]}]
            parts:
              - chain: {name: c, parent: anchor, bones: 6, length: 0.5, direction: [1, 0, 0]}
        cloths:
          - name: chain
            root_bones: [c_0]
            connection: line
            parameters:
              damping: 0.5
              angle_restoration.use: false
              angle_limit.use: false
        """)
    run = run_variant(Variant("hanging", path))
    p = run.positions[-1]
    assert np.abs(p[:, 0] - p[0, 0]).max() < 1e-6       # straight down under the root (measured 1.6e-9 m)
    assert np.abs(p[:, 2] - p[0, 2]).max() < 1e-9
    assert np.all(np.diff(p[:, 1]) < 0)                   # each particle below its parent
    lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
    # MagicaCloth2's distance constraint is soft (Appendix 4: +1.8 % root distance for 5
    # links of 0.1 m at the default gravity 5): the lengths are not exact. Measured here, root
    # to tip: +1.29, +2.10, +1.78, +1.25, +0.35 %; all longer, none beyond 2.5 %.
    assert np.all(lengths > 0.1)
    assert np.abs(lengths / 0.1 - 1.0).max() < 0.025
    assert run.display_speed[-60:].max() < 1e-3           # and it is at rest


def rotation_scene(tmp_path, inertia):
    return scene_file(tmp_path, f"rot{inertia}", f"""
        version: 1
        scene: {{name: rot, fps: 60, duration: 4.0}}
        rigs:
          - name: r
            bones: [{{name: anchor, position: [0, 1, 0]}}]
            parts:
              - chain: {{name: c, parent: anchor, bones: 6, length: 0.5, direction: [1, -0.3, 0.4], curl: 10}}
        animation:
          - {{target: anchor, spin: {{axis: [0.3, 1, 0.2], speed: 90}}, end: 2.0}}
        cloths:
          - name: chain
            root_bones: [c_0]
            connection: line
            parameters:
              gravity: 0
              angle_restoration.stiffness: 1
              inertia.world_inertia: {inertia}
              inertia.local_inertia: {inertia}
        """)


def shape_error(run, scene_nodes_rest):
    """Largest distance (fraction of chain length) of a particle from where the rigidly
    rotated rest shape puts it, at every frame."""
    p = run.positions
    rest = scene_nodes_rest
    err = 0.0
    for f in range(p.shape[0]):
        # best rotation of the rest offsets onto the current offsets (Kabsch), root at origin
        a = rest - rest[0]
        b = p[f] - p[f, 0]
        u, _, vt = np.linalg.svd(a.T @ b)
        d = np.sign(np.linalg.det(u @ vt))
        r = u @ np.diag([1, 1, d]) @ vt
        err = max(err, float(np.linalg.norm(a @ r - b, axis=1).max()))
    return err / run.geometry.chain_length


def rest_positions(path):
    from magica_py.config import load_scene

    scene = load_scene(path)
    scene.hierarchy.propagate()
    names = [f"c_{i}" for i in range(6)]
    return np.array([scene.hierarchy.world_position[scene.hierarchy.index(n)] for n in names])


def test_rigid_body_invariance_with_inertia_zero_is_exact(tmp_path):
    path = rotation_scene(tmp_path, 0.0)
    run = run_variant(Variant("rot0", path))
    assert shape_error(run, rest_positions(path)) < 1e-9


def test_rigid_body_invariance_with_restoration_one_keeps_the_shape(tmp_path):
    """World and local inertia 1 (the particles feel the rotation), restoration stiffness 1,
    no gravity: the shape bends while the root spins at 90 deg/s and comes back after.
    (Restoration is a per-step pull of 0.2, not a rigid constraint: the bend is the finding.)"""
    path = rotation_scene(tmp_path, 1.0)
    run = run_variant(Variant("rot1", path))
    rest = rest_positions(path)
    during = shape_error(run, rest)
    assert during < 0.05                          # measured 1.9 % of the chain while spinning
    run.positions = run.positions[-1:]
    assert shape_error(run, rest) < 5e-4          # 2 s after the spin: measured 1.2e-4


def positions_hash(path, seconds=0.5):
    run = run_variant(Variant("det", path, duration=seconds))
    return hashlib.sha256(np.ascontiguousarray(run.positions).tobytes()).hexdigest()


def test_determinism_across_processes():
    from magica_py.bench.variants import resolve_scene_path

    path = resolve_scene_path("character_walk")
    here = positions_hash(path)
    code = ("import sys; sys.path.insert(0, 'tests'); from test_analytic import positions_hash; "
            f"print(positions_hash({path!r}))")
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == here
