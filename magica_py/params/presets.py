"""The 11 presets shipped with MagicaCloth2 (docs/solver.md §F.2, ``MC2_Preset_*.json``).

Each preset is a dict of the parameter keys it sets; every other key keeps the table
default. Curves are ``Curve.hermite(value, (v0, out_slope0), (v1, in_slope1), use)`` — the
two tangents that enter Unity's Hermite formula (weights ignored: weightedMode = 0).
Common to every preset (and equal to the defaults): line connection, rotational
interpolation 0.5, root rotation 0.5, stabilization 0.1, blend weight 1, radius 0.02,
world inertia 1, smoothing 0.4, anchor inertia 0, teleport none, point collision, motion
off. Wind influence is recorded although wind zones do not exist in scene format v1.
"""
from __future__ import annotations

from magica_py.params.curves import Curve

_SPRING_RESTORE_KEYS = ((1.0, 0.0), (0.5023, -0.8))
_SKIRT_LIMIT = ((0.1997, 0.8003), (1.0, 0.8003))


def _local_limits(move, rot=360.0):
    return {"inertia.local_movement_speed_limit": move, "inertia.local_rotation_speed_limit": rot}


def _spring(restore_value, attenuation, damping):
    return {
        "gravity": 0.0, "gravity_falloff": 0.0, "damping": Curve.flat(damping),
        "tether.distance_compression": 0.099, "distance.stiffness": Curve.linear(0.242, 1.0, 0.5, False),
        "triangle_bending.stiffness": 0.241,
        "angle_restoration.stiffness": Curve.hermite(restore_value, *_SPRING_RESTORE_KEYS),
        "angle_restoration.velocity_attenuation": attenuation, "angle_restoration.gravity_falloff": 0.0,
        "angle_limit.use": False,
        "inertia.movement_speed_limit": 1.0, "inertia.rotation_speed_limit": 360.0, **_local_limits(1.0),
        "inertia.particle_speed_limit": 4.0, "collider_collision.friction": 0.2, "wind.influence": 0.2,
    }


PRESETS: dict[str, dict] = {
    "tail": {
        "gravity": 0.0, "gravity_falloff": 0.0, "damping": Curve.flat(0.05),
        "tether.distance_compression": 0.5, "distance.stiffness": Curve.linear(1.0, 1.0, 0.5, False),
        "triangle_bending.stiffness": 0.5,
        "angle_restoration.stiffness": Curve.hermite(0.1, (1.0, -1.5033), (0.09733, -0.17397)),
        "angle_restoration.velocity_attenuation": 0.5, "angle_restoration.gravity_falloff": 0.0,
        "angle_limit.use": False, "angle_limit.limit_angle": Curve.hermite(80.0, (0.0, 1.0), (1.0, 1.0)),
        "angle_limit.stiffness": 1.0,
        **_local_limits(3.0), "inertia.particle_speed_limit": 4.0,
        "collider_collision.friction": 0.05, "wind.influence": 0.2,
    },
    "short_hair": {
        "gravity": 2.0, "gravity_falloff": 1.0, "damping": Curve.flat(0.1),
        "tether.distance_compression": 0.2, "distance.stiffness": Curve.linear(1.0, 1.0, 0.5, False),
        "triangle_bending.stiffness": 1.0,
        "angle_restoration.stiffness": Curve.hermite(0.15, (1.0, -0.7), (0.3, -0.7)),
        "angle_restoration.velocity_attenuation": 0.6, "angle_restoration.gravity_falloff": 0.0,
        "angle_limit.use": True, "angle_limit.limit_angle": Curve.hermite(45.0, *_SKIRT_LIMIT),
        "angle_limit.stiffness": 1.0,
        **_local_limits(1.0), "inertia.depth_inertia": 1.0, "inertia.particle_speed_limit": 4.0,
        "collider_collision.friction": 0.05, "wind.influence": 0.2,
    },
    "long_hair": {
        "gravity": 5.0, "gravity_falloff": 0.0, "damping": Curve.flat(0.1),
        "tether.distance_compression": 0.4, "distance.stiffness": Curve.linear(1.0, 1.0, 0.5, False),
        "triangle_bending.stiffness": 1.0,
        "angle_restoration.stiffness": Curve.hermite(0.2, (1.0, -2.2792), (0.1062, -0.4004)),
        "angle_restoration.velocity_attenuation": 0.8, "angle_restoration.gravity_falloff": 0.5,
        "angle_limit.use": True, "angle_limit.limit_angle": Curve.hermite(75.0, (0.2017, 1.9016), (1.0, 0.3574)),
        "angle_limit.stiffness": 0.3,
        **_local_limits(3.0), "inertia.particle_speed_limit": 3.0,
        "collider_collision.friction": 0.05, "wind.influence": 0.2,
    },
    "front_hair": {
        "gravity": 4.0, "gravity_falloff": 0.8, "damping": Curve.flat(0.1),
        "tether.distance_compression": 0.1, "distance.stiffness": Curve.linear(1.0, 1.0, 0.5, False),
        "triangle_bending.stiffness": 1.0,
        "angle_restoration.stiffness": Curve.hermite(0.15, (1.0, -0.7), (0.3, -0.7)),
        "angle_restoration.velocity_attenuation": 0.7, "angle_restoration.gravity_falloff": 0.5,
        "angle_limit.use": True, "angle_limit.limit_angle": Curve.hermite(15.0, (0.0, 1.0), (1.0, 1.0)),
        "angle_limit.stiffness": 0.5,
        "inertia.movement_speed_limit": 3.0, "inertia.rotation_speed_limit": 360.0,
        "inertia.particle_speed_limit": 2.0, "collider_collision.friction": 0.05, "wind.influence": 1.0,
    },
    "skirt": {
        "gravity": 5.0, "gravity_falloff": 0.0, "damping": Curve.flat(0.1),
        "tether.distance_compression": 0.3, "distance.stiffness": Curve.hermite(1.0, (1.0, -0.5), (0.5, -0.5)),
        "triangle_bending.stiffness": 1.0,
        "angle_restoration.stiffness": Curve.hermite(0.2, (1.0, -0.7955), (0.2045, -0.7955)),
        "angle_restoration.velocity_attenuation": 0.7, "angle_restoration.gravity_falloff": 0.0,
        "angle_limit.use": True, "angle_limit.limit_angle": Curve.hermite(60.0, *_SKIRT_LIMIT),
        "angle_limit.stiffness": 1.0,
        **_local_limits(3.0), "inertia.depth_inertia": 0.7, "inertia.centrifugal_acceleration": 0.1,
        "inertia.particle_speed_limit": 4.0, "collider_collision.friction": 0.05, "wind.influence": 0.2,
    },
    "soft_skirt": {
        "gravity": 3.0, "gravity_falloff": 0.0, "damping": Curve.flat(0.1),
        "tether.distance_compression": 0.3, "distance.stiffness": Curve.hermite(1.0, (1.0, 0.0), (0.0434, -0.2015)),
        "triangle_bending.stiffness": 0.23,
        "angle_restoration.stiffness": Curve.hermite(0.14, (1.0, -0.9403), (0.0597, -0.2857)),
        "angle_restoration.velocity_attenuation": 0.7, "angle_restoration.gravity_falloff": 0.0,
        "angle_limit.use": False, "angle_limit.limit_angle": Curve.hermite(60.0, *_SKIRT_LIMIT),
        "angle_limit.stiffness": 1.0,
        **_local_limits(3.0), "inertia.depth_inertia": 0.25, "inertia.centrifugal_acceleration": 0.1,
        "inertia.particle_speed_limit": 4.0, "collider_collision.friction": 0.05, "wind.influence": 0.2,
    },
    "cape": {
        "gravity": 7.0, "gravity_falloff": 0.0, "damping": Curve.flat(0.1),
        "tether.distance_compression": 0.5, "distance.stiffness": Curve.linear(1.0, 1.0, 0.5, False),
        "triangle_bending.stiffness": 1.0,
        "angle_restoration.stiffness": Curve.hermite(0.15, (1.0, 0.0), (0.0968, -0.7)),
        "angle_restoration.velocity_attenuation": 0.8, "angle_restoration.gravity_falloff": 0.0,
        "angle_limit.use": True, "angle_limit.limit_angle": Curve.hermite(45.0, (0.0, 2.0), (1.0, 0.0)),
        "angle_limit.stiffness": 1.0,
        "inertia.depth_inertia": 0.7, "inertia.particle_speed_limit": 4.0,
        "collider_collision.friction": 0.1, "wind.influence": 1.0,
    },
    "accessory": {
        "gravity": 0.0, "gravity_falloff": 0.0, "damping": Curve.flat(0.1),
        "tether.distance_compression": 0.1, "distance.stiffness": Curve.linear(1.0, 1.0, 0.5, False),
        "triangle_bending.stiffness": 1.0,
        "angle_restoration.stiffness": Curve.flat(0.15),
        "angle_restoration.velocity_attenuation": 0.6, "angle_restoration.gravity_falloff": 0.0,
        "angle_limit.use": True, "angle_limit.limit_angle": Curve.flat(45.0), "angle_limit.stiffness": 1.0,
        "inertia.particle_speed_limit": 4.0, "collider_collision.friction": 0.05, "wind.influence": 1.0,
    },
    "hard_spring": _spring(0.6, 0.4, 0.3),
    "middle_spring": _spring(0.4, 0.6, 0.3),
    "soft_spring": _spring(0.2, 0.8, 0.2),
}
