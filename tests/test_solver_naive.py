"""The numba step against the plain-numpy reference of ``naive_step.py`` (float tolerance).

One step of the lane form (``frame.run_step`` of the team's block on ``system.tables``) after
a few frames of the real system, against ``naive_step`` on copies of the same state read
through the team-ordered views (``system.particles`` / ``teams`` / ``collider_state``), the
team's build model and its parameters."""
from __future__ import annotations

import numpy as np
import pytest

from magica_py.scene.hierarchy import BoneSpec
from magica_py.solver.frame import FrameInputs, run_step
from naive_step import naive_step
from solver_scenes import chain_system, params, run


def table(view):
    return {name: np.array(getattr(view, name)) for name in view.fields}


def naive_inputs(s, team=0):
    """(M, S, P, T, C) for ``naive_step``: dicts of copies, team-ordered, indexed by team id
    (team-level arrays) or by the team-ordered particle / collider index."""
    model = s.models[team]
    m = s.model
    assert m.team_particle_start[team] == 0 and len(s.live_teams) == 1   # one team: its indices are global
    M = {name: np.array(getattr(m, name)) for name in m._fields}
    for name in ("baseline_start", "baseline_count", "baseline_data", "distance_start", "distance_count",
                 "distance_target", "distance_rest", "baseline_local_position", "baseline_local_rotation"):
        M[name] = np.array(getattr(model, name))
    M["team_baseline_start"] = np.array([0])
    M["team_baseline_count"] = np.array([len(model.baseline_start)])
    M["team_init_local_gravity"] = np.array([model.init_local_gravity_direction], dtype=np.float64)
    P = {name: np.array(getattr(s.parameters, name)) for name in s.parameters._fields}
    T = table(s.teams)
    T["collider_start"] = np.array([m.team_collider_start[team]])
    T["collider_count"] = np.array([m.team_collider_count[team]])
    C = table(s.collider_state)
    b, _lane = s.layout.place(team)
    C["shape"] = np.array(s.layout.segment(b, "collider_shape"))
    return M, table(s.particles), P, T, C


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
    s.write_team(0, "frame_interpolation", frac)      # what the step's A.6 writes for the lane
    M, S, P, T, C = naive_inputs(s)
    naive_step(M, S, P, T, C, 0, frac, 1.0 / 90.0)
    fi = FrameInputs(1 / 60, 1 / 60, 0.02, 0, 1.0, 1.0 / 90.0, 3, 0, 1.0, 1.0, 1.0, 1.0, 1)
    b, _lane = s.layout.place(0)
    stages = s.stages
    run_step(s.tables, np.int32(b), fi, stages.angle, stages.bending, stages.point_collision,
             stages.edge_collision, stages.motion, stages.quality, stages.wind, None, stages.colliders)
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
