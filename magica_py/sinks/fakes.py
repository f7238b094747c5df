"""Fake scene data for tests of sinks (and of anything that drives one): a two-chain rig, two cloths, one collider per shape."""
from __future__ import annotations

import numpy as np

from magica_py.sinks.base import (ClothTopology, ColliderShapes, FrameData, LogToggles,
                                  ReplayFrame, SceneStatics)

JOINT_NAMES = ["root", "a0", "a1", "a2", "b0", "b1"]
JOINT_PARENT = np.array([-1, 0, 1, 2, 0, 4], np.int32)
COLLIDER_NAMES = ("ball", "arm", "floor")      # one sphere, one tapered capsule, one plane (colliders_frame)


def topologies():
    line = ClothTopology(
        name="tail", attribute=np.array([1, 2, 2], np.uint8), radius=np.array([0.02, 0.02, 0.03]),
        parent=np.array([-1, 0, 1], np.int32), edges=np.array([[0, 1], [1, 2]], np.int32),
        triangles=np.zeros((0, 3), np.int32), rest_length=np.array([0.1, 0.1]),
        transform_index=np.array([1, 2, 3], np.int32), colliders=np.array([0, 1, 2], np.int32))
    mesh = ClothTopology(
        name="skirt#1", attribute=np.array([1, 1, 2, 2], np.uint8), radius=np.full(4, 0.01),
        parent=np.array([-1, -1, 0, 1], np.int32), edges=np.array([[0, 1], [0, 2], [1, 3], [2, 3], [1, 2]], np.int32),
        triangles=np.array([[0, 2, 1], [1, 2, 3]], np.int32), rest_length=np.array([0.1, 0.1, 0.1, 0.1, 0.1414]),
        transform_index=np.array([4, 5, 4, 5], np.int32), colliders=np.zeros(0, np.int32))
    return [line, mesh]


def statics(toggles=None):
    return SceneStatics(name="fake", joint_names=JOINT_NAMES, joint_parent=JOINT_PARENT, cloths=topologies(),
                        toggles=toggles or LogToggles(baselines=True, base_pose=True),
                        replay_node_names=["root"], replay_scene_text="scene: {name: fake}\n",
                        time_fields=("time", "delta_time"), node_group=[""] * len(JOINT_NAMES),
                        collider_names=list(COLLIDER_NAMES))


def colliders_frame(f):
    return ColliderShapes(
        sphere_center=np.array([[0.0, 0.5 + 0.01 * f, 0.0]]), sphere_radius=np.array([0.1]),
        capsule_start=np.array([[0.2, 0.0, 0.0]]), capsule_end=np.array([[0.2, 0.4, 0.0]]),
        capsule_start_radius=np.array([0.05]), capsule_end_radius=np.array([0.04]),
        plane_point=np.zeros((1, 3)), plane_normal=np.array([[0.0, 1.0, 0.0]]))


def trajectory(frames, seed=0):
    """Per frame: joints (6,3), tail (3,3), skirt (4,3) as float64 with bits float32 cannot keep."""
    rng = np.random.default_rng(seed)
    return [(rng.random((6, 3)) + 1.0 / 3.0, rng.random((3, 3)) + 1.0 / 7.0, rng.random((4, 3)))
            for _ in range(frames)]


def frame_data(f, joints, tail, skirt, dt=1 / 60):
    return FrameData(
        frame=f, sim_time=f * dt, delta_time=dt, joint_positions=joints,
        positions=np.vstack([tail, skirt]), base_positions=np.vstack([tail, skirt]) * 0.5, steps=2,
        colliders=colliders_frame(f),
        metrics={"time.late_update": 0.002, "time.update": 0.001},
        events=[("teleport", {"target": "root", "frame": f})] if f == 3 else [],
        replay=ReplayFrame(local_position=joints[:1], local_rotation=np.array([[0.0, 0.0, 0.0, 1.0]]),
                           local_scale=np.ones((1, 3)), time_values=np.array([f * dt, dt]),
                           events_json='[["teleport", {}]]' if f == 3 else ""))
