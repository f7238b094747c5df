"""The angle stage's lean pass (``angle_iteration_lanes`` with ``full`` False: no limit
violation path, no opposite-vector paths) followed by the full pass on the lanes it flagged
gives every lane the bits of the full path, on lanes whose edge is exactly opposite its rest
direction (the restoration's opposite turn) or its limit direction (the swing's opposite
path) among ordinary ones, with and without the limit."""
import math

import numpy as np
import pytest

from magica_py.solver import state as st
from magica_py.solver.constraints.angle import angle_iteration_lanes
from magica_py.solver.lanes import LANES

ROWS = ((st.NEXT_POS, 3), (st.VELOCITY_POS, 3), (st.PARTNER_POS, 3), (st.PARTNER_VELOCITY_POS, 3),
        (st.ANGLE_ROTATION, 4))


def _put(PS, field, values):
    values = np.asarray(values, dtype=np.float64).reshape(LANES, -1)
    for k in range(values.shape[1]):
        PS[0, field + k * LANES:field + (k + 1) * LANES] = values[:, k]


def _get(PS, field, size):
    return np.stack([PS[0, field + k * LANES:field + (k + 1) * LANES] for k in range(size)], axis=1)


def _unit(x):
    return x / np.linalg.norm(x, axis=1)[:, None]


def _slot(rng, restoration_opposite, limit_opposite):
    """One child slot's rows for 16 lanes: random edges, rest and limit directions, with the
    listed lanes' rest direction (or limit direction) exactly opposite the edge."""
    PS = st.PARTICLE.allocate(1)
    pp = rng.uniform(-2.0, 2.0, (LANES, 3))
    edge = _unit(rng.normal(size=(LANES, 3))) * rng.uniform(0.05, 0.2, (LANES, 1))
    cp = pp + edge
    rest = _unit(rng.normal(size=(LANES, 3)))
    rest[restoration_opposite] = -_unit(edge[restoration_opposite])
    # the limit: the parent's rotation is the identity, so the limit direction is local_pos
    local = _unit(edge + rng.normal(scale=0.3, size=(LANES, 3)))
    local[limit_opposite] = -_unit(edge[limit_opposite])
    _put(PS, st.NEXT_POS, cp)
    _put(PS, st.PARTNER_POS, pp)
    _put(PS, st.VELOCITY_POS, cp - 0.01)
    _put(PS, st.PARTNER_VELOCITY_POS, pp + 0.01)
    _put(PS, st.ANGLE_INVERSE_MASS, rng.uniform(0.5, 1.0, LANES))
    _put(PS, st.PARTNER_W, rng.uniform(0.5, 1.0, LANES))
    _put(PS, st.ANGLE_ROTATION, _unit(rng.normal(size=(LANES, 4))))
    _put(PS, st.PARTNER_ROTATION, np.tile([0.0, 0.0, 0.0, 1.0], (LANES, 1)))
    _put(PS, st.ANGLE_LOCAL_POS, local)
    _put(PS, st.ANGLE_LOCAL_ROT, _unit(rng.normal(size=(LANES, 4))))
    _put(PS, st.ANGLE_LENGTH, np.linalg.norm(edge, axis=1) * rng.uniform(0.9, 1.1, LANES))
    limit = np.full(LANES, math.radians(170.0))       # wide: only the opposite lanes violate it
    _put(PS, st.ANGLE_LIMIT, limit)
    _put(PS, st.ANGLE_LIMIT_COS, np.cos(limit))
    _put(PS, st.ANGLE_REST_LENGTH, np.full(LANES, 0.1))
    _put(PS, st.ANGLE_REST_DIRECTION, rest)
    _put(PS, st.ANGLE_RESTORATION_K, rng.uniform(0.1, 0.9, LANES))
    _put(PS, st.ANGLE_RARE, np.zeros(LANES))
    return PS


def _iterate(PS, use_limit, full):
    angle_iteration_lanes(PS, 0, LANES, True, 0.3, use_limit, True, 0.5, 0.9, 0.8, np.bool_(full))


@pytest.mark.parametrize("use_limit", [False, True])
def test_the_lean_pass_then_the_full_pass_give_the_full_paths_bits_on_opposite_lanes(use_limit):
    rng = np.random.default_rng(5)
    restoration_opposite = [2, 9]
    limit_opposite = [5, 12] if use_limit else []
    lean = _slot(rng, restoration_opposite, limit_opposite)
    full = lean.copy()
    # as angle_block runs it: the lean pass, then the full pass where a lane was flagged
    _iterate(lean, use_limit, False)
    flagged = _get(lean, st.ANGLE_RARE, 1)[:, 0] != 0.0
    assert set(np.flatnonzero(flagged)) >= set(restoration_opposite + limit_opposite)
    _iterate(lean, use_limit, True)
    # every lane on the full path
    _put(full, st.ANGLE_RARE, np.ones(LANES))
    _iterate(full, use_limit, True)
    for field, size in ROWS:
        a, b = _get(lean, field, size), _get(full, field, size)
        assert np.all(np.isfinite(a))
        assert a.tobytes() == b.tobytes(), (field, np.flatnonzero((a != b).any(axis=1)))
    # the opposite lanes did turn: the child moved off its edge's line
    moved = _get(lean, st.NEXT_POS, 3) - _get(_slot(np.random.default_rng(5), restoration_opposite, limit_opposite),
                                              st.NEXT_POS, 3)
    assert np.all(np.linalg.norm(moved[restoration_opposite], axis=1) > 1e-4)
