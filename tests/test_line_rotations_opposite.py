"""E.2 on an edge exactly opposite its rest direction: the line rotations' lean pass leaves the
opposite paths out (``line_child_lanes`` and ``line_turn`` with ``full`` False) and redoes the
lanes that need them, so such a lane gets the reference's half turn about ``orthogonal_axis``
(docs/solver.md §0.2 fromto_v) while its neighbours keep their own results.

A block of 16 two-bone chains of the light scene (a fixed root and one moving child); one lane's
child is moved so that its simulated edge points against its rest edge: lane 5, and lane 13 (a
full block's lean turn runs lanes h and h + 8 side by side, ``line_turn_pairs``). Hand-written expected
values: the child's rotation is ``rot(ortho(a), pi) * (Q * lq)`` and the root's
``rot(ortho(a), pi * root_rotation) * Q``, with a the unit rest edge, Q the root's animated
rotation and lq the child's rest rotation (the branching maths of ``kernels.math3d``)."""
import math
import pathlib

import numpy as np
import pytest

from magica_py.config import load_scene
from magica_py.kernels.math3d import orthogonal_axis, q_axis_angle, q_mul, q_rotate, v_normalize
from magica_py.runtime.player import Player
from magica_py.solver import blocks as bk
from magica_py.solver import state as st
from magica_py.solver.lanes import LANES
from magica_py.solver.parameters import PRM_ROOT_ROTATION
from magica_py.solver.rotations import line_rotations_block
from magica_py.solver.system import ClothSystem

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _get(table, g, field, size, lane):
    return tuple(float(table[g, field + k * LANES + lane]) for k in range(size))


def _put(table, g, field, values, lane):
    for k, v in enumerate(values):
        table[g, field + k * LANES + lane] = v


def _rotations(T, b, PS, gx, gc):
    """ROTATION rows of the root and the child after E.2 on the particle state PS."""
    T.PS[:] = PS
    line_rotations_block(T.PS, T.PM, T.TS, T.P, T.BI, T.topology, b)
    rows = [st.ROTATION + k * LANES for k in range(4)]
    return (T.PS[gx, rows[0]:rows[0] + 4 * LANES].copy(), T.PS[gc, rows[0]:rows[0] + 4 * LANES].copy())


@pytest.mark.parametrize("lane", [5, 13])
def test_an_edge_opposite_its_rest_direction_turns_half_about_the_orthogonal_axis(lane):
    scene = load_scene(ROOT / "configs" / "light_chains.yaml",
                       overrides=["rigs.0.instances.count=16", "rigs.0.parts.0.chain.bones=2",
                                  "rigs.0.parts.0.chain.length=0.1"])
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings).attach(player)
    player.run(20)
    T = system.tables
    (b,) = T.blocks
    assert bk.lane_width(T.BI, b) == LANES and T.BI[b, bk.BI_N] == 2
    g0 = T.BI[b, bk.BI_G0]
    gx, gc = g0, g0 + 1   # the fixed root and its moving child
    # E.2's input as the frame leaves it: display positions, animated rotations (E.1)
    original = T.PS.copy()
    q_root = _get(original, gx, st.ROTATION, 4, lane)
    tv = q_rotate(q_root, _get(T.PM, gc, bk.BASELINE_LOCAL_POSITION, 3, lane))
    root_position = _get(original, gx, st.POSITION, 3, lane)
    flipped = original.copy()
    _put(flipped, gc, st.POSITION, tuple(p - v for p, v in zip(root_position, tv)), lane)

    root_rows, child_rows = _rotations(T, b, flipped, gx, gc)
    root = tuple(root_rows[k * LANES + lane] for k in range(4))
    child = tuple(child_rows[k * LANES + lane] for k in range(4))
    a = v_normalize(tv)
    lq = _get(T.PM, gc, bk.BASELINE_LOCAL_ROTATION, 4, lane)
    child_expected = q_mul(q_axis_angle(orthogonal_axis(a), math.pi), q_mul(q_root, lq))
    root_expected = q_mul(q_axis_angle(orthogonal_axis(a), math.pi * T.P[b, PRM_ROOT_ROTATION]), q_root)
    assert np.allclose(child, child_expected, rtol=0.0, atol=1e-15), (child, child_expected)
    assert np.allclose(root, root_expected, rtol=0.0, atol=1e-15), (root, root_expected)
    # the child's half turn takes its rest edge onto the simulated one, against it
    edge = np.subtract(_get(flipped, gc, st.POSITION, 3, lane), root_position)
    turned = q_rotate(child, q_rotate((-lq[0], -lq[1], -lq[2], lq[3]), q_rotate(
        (-q_root[0], -q_root[1], -q_root[2], q_root[3]), tv)))
    assert np.allclose(turned, edge, rtol=0.0, atol=1e-12)

    # every other lane: the bits E.2 gives it when no lane of the block is opposite
    plain_root, plain_child = _rotations(T, b, original, gx, gc)
    others = np.array([[k * LANES + l for l in range(LANES) if l != lane] for k in range(4)]).ravel()
    assert root_rows[others].tobytes() == plain_root[others].tobytes()
    assert child_rows[others].tobytes() == plain_child[others].tobytes()
    assert not np.allclose(child, plain_child[[k * LANES + lane for k in range(4)]])
