"""C.1's build half (``blocks.bound_vectors``: each vertex's bind pose applied to its build
position, normal and tangent once, when its lane is written) against the per-frame form it
replaced, the frozen reference solver's compiled ``bind_point``: the same bits on random and
signed-zero inputs and on a built character's vertices, and hand-written values."""
import pathlib

import numba
import numpy as np

from magica_py.solver.blocks import bound_vectors
from reference_solver.solver.center import bind_point


@numba.njit(cache=False, error_model="numpy")
def _reference_bound(B, p, n, t):
    out = np.empty((B.shape[0], 3, 4))
    for i in range(B.shape[0]):
        rows = [(B[i, r, 0], B[i, r, 1], B[i, r, 2], B[i, r, 3]) for r in range(4)]
        for k in range(3):
            v = p[i] if k == 0 else (n[i] if k == 1 else t[i])
            x = bind_point(rows[0], rows[1], rows[2], rows[3], (v[0], v[1], v[2]), 1.0 if k == 0 else 0.0)
            for c in range(4):
                out[i, k, c] = x[c]
    return out


def _bits(a):
    return np.ascontiguousarray(a).view(np.uint64)


def test_bound_vectors_give_the_per_frame_bind_points_bits_on_random_inputs():
    rng = np.random.default_rng(7)
    n = 2000
    B = rng.normal(size=(n, 4, 4)) * rng.choice([1e-3, 1.0, 1e3], size=(n, 4, 4))
    B[: n // 4, 3] = (0.0, 0.0, 0.0, 1.0)          # affine rows, as a TRS inverse has
    p, nor, tan = (rng.normal(size=(n, 3)) for _ in range(3))
    # signed zeros and exact zeros, where the order of the sums decides the sign of the result
    for a in (B, p, nor, tan):
        mask = rng.random(a.shape) < 0.15
        a[mask] = rng.choice([0.0, -0.0], size=int(mask.sum()))
    assert np.array_equal(_bits(bound_vectors(B, p, nor, tan)), _bits(_reference_bound(B, p, nor, tan)))


def test_bound_vectors_of_built_cloths_give_the_reference_bits():
    """Every cloth of the character and the crowd showcase (line, mesh and skirt rigs, bind
    poses with real round-off)."""
    from magica_py.build import build_cloth
    from magica_py.config import load_scene

    root = pathlib.Path(__file__).resolve().parent.parent
    checked = 0
    for config in ("character_walk", "crowd"):
        scene = load_scene(root / "configs" / f"{config}.yaml")
        for spec in scene.cloths:
            m = build_cloth(scene.hierarchy, spec, cache=None)
            B = np.ascontiguousarray(m.skin_bind_pose, dtype=np.float64).reshape(-1, 4, 4)
            args = [np.ascontiguousarray(a, dtype=np.float64)
                    for a in (m.local_position, m.local_normal, m.local_tangent)]
            assert np.array_equal(_bits(bound_vectors(B, *args)), _bits(_reference_bound(B, *args)))
            checked += B.shape[0]
    assert checked > 100


def test_bound_vectors_of_identity_and_translation_bind_poses():
    B = np.stack([np.eye(4), np.eye(4)])
    B[1, :3, 3] = (1.0, -2.0, 0.5)                  # a translation by (1, -2, 0.5)
    p = np.array([[0.1, 0.2, 0.3], [0.1, 0.2, 0.3]])
    nor = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    tan = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    out = bound_vectors(B, p, nor, tan)
    assert out.shape == (2, 3, 4)
    assert np.array_equal(out[0], [[0.1, 0.2, 0.3, 1.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    # the position moves with the translation; directions (w = 0) do not
    assert np.array_equal(out[1], [[1.1, -1.8, 0.8, 1.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
