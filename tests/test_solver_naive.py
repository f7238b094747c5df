"""The numba step against the plain-numpy reference of ``naive_step.py`` (float tolerance)."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.scene.hierarchy import BoneSpec
from magica_py.solver.frame import FrameInputs, run_step
from naive_step import naive_step
from solver_scenes import chain_system, params, run


def table(soa):
    return {name: np.array(getattr(soa, name)) for name in soa._fields}


def swinging_scene(**overrides):
    extra = [BoneSpec("ball", None, (0.0, 0.72, -0.3)), BoneSpec("floor", None, (0.0, 0.6, 0.0))]
    colliders = [{"name": "ball", "transform": "ball", "sphere": {"radius": 0.1}},
                 {"name": "floor", "transform": "floor", "plane": {}}]
    s, h = chain_system(bones=6, length=0.6, direction=(0.0, 0.0, -1.0), extra_bones=extra,
                        collider_specs=colliders, collision_mode="point",
                        parameters=params(**overrides))
    return s, h


@pytest.mark.parametrize("frames", [3, 25, 60])
@pytest.mark.parametrize("overrides", [{}, {"motion__use_max_distance": True, "motion__max_distance": 0.25,
                                            "inertia__local_inertia": 0.5, "damping": 0.2}])
def test_numba_step_matches_the_numpy_reference(frames, overrides):
    s, h = swinging_scene(**overrides)
    root = h.index("root")

    def move(f):  # the root moves so that inertia, shifts and colliders' history matter
        h.local_position[root] = (0.01 * f, 1.0, 0.005 * f)
    run(s, frames, before=move)
    frac = 0.4
    s.time_state.frame_interpolation[0] = frac
    M, S, P, T, C = (table(x) for x in (s.model, s.particles, s.parameters, s.teams, s.collider_state))
    naive_step(M, S, P, T, C, 0, frac, 1.0 / 90.0)
    fi = FrameInputs(1 / 60, 1 / 60, 0.02, 0, 1.0, 1.0 / 90.0, 3, 0, 1.0, 1.0, 1.0, 1.0, 1)
    m, ps, prm, ts, cs, tt, _h = s.kernel_tables()
    run_step(m, ps, prm, ts, cs, tt, 0, fi, *s.stages[:6], s.stages.wind)  # angle ... quality, wind
    for name in ("next_pos", "old_pos", "velocity_pos", "velocity", "real_velocity", "base_pos",
                 "step_basic_pos", "friction", "static_friction", "collision_normal"):
        np.testing.assert_allclose(getattr(s.particles, name), S[name], rtol=0, atol=1e-10, err_msg=name)
    for name in ("now_world_pos", "old_world_pos", "velocity_weight", "blend_weight", "scale_ratio"):
        np.testing.assert_allclose(getattr(s.teams, name), T[name], rtol=0, atol=1e-12, err_msg=name)
    for name in ("now_pos", "old_pos", "radius_start"):
        np.testing.assert_allclose(getattr(s.collider_state, name), C[name], rtol=0, atol=1e-12, err_msg=name)
    # the scene is not trivial: particles touch a collider and move
    if frames >= 25 and not overrides:      # (max distance keeps the tail off the colliders)
        assert np.abs(s.particles.collision_normal).sum() > 0.0
    assert np.abs(s.particles.velocity).max() > 0.01
