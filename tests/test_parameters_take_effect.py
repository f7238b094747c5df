"""Every cloth parameter does what docs/parameters.md says, and none is accepted with no effect.

For each row of the parameter table (``magica_py/params/table.py``; the tests are parametrised
over the table itself, so a new parameter without an entry in ``CASES`` fails here), a small
scene where the parameter should matter is run twice for one second (60 frames): once with the
default and once with a clearly different value. The final display positions or bone
rotations must differ, in the direction the documentation implies where it says one (a
``metric`` of the two runs, compared with ``sign``). The scene-level settings the parameters
work with (curve shapes, colliders, wind zones, timing) have their own table, ``SUB_CASES``.
Every value of the table is also checked to be validated (an out-of-range or ill-typed value is
a ``ConfigError`` naming ``cloths[0].parameters.<key>``), and one run is repeated to the bit.

The scenes are line chains of 6 bones (a sheet or a skirt where a mesh matters), built from
YAML text through ``magica_py.simulate``: after numba's cache is warm a run takes ~15 ms, and
runs are cached by their scene text, so the default and animated-pose runs are shared.
"""
from __future__ import annotations

import copy
import functools

import numpy as np
import pytest
import yaml

import magica_py
from magica_py.params import PARAMETER_DEFS, default_parameters
from magica_py.params.table import INTEGER_PARAMETERS

FRAMES = 60
BALL = np.array([0.0, 0.85, -0.35])


# ----------------------------------------------------------------------------- scenes
def scene(kind: str, params: dict | None = None) -> dict:
    """A scene document of ``kind`` whose cloth ``tail`` has ``params`` (dotted keys)."""
    bones = [{"name": "root", "position": [0, 1, 0]}]
    parts = [{"chain": {"name": "tail", "parent": "root", "bones": 6, "length": 0.6, "direction": [0, 0, -1]}}]
    anim, colliders, wind = [], [], None
    cloth = {"name": "tail", "root_bones": ["tail_0"], "connection": "line"}
    wind_zone = {"name": "breeze", "mode": "global", "main": 4.0, "turbulence": 0.8, "direction": [1, 0, 0]}
    if kind == "swing":      # the root flies a circle facing its path and nods
        anim += [{"target": "root", "orbit": {"center": [0, 1, 0], "radius": 0.4, "period": 1.5,
                                              "axis": [0, 1, 0], "face_path": True}},
                 {"target": "root", "oscillate": {"property": "rotation", "axis": [1, 0, 0], "amplitude": 30,
                                                  "frequency": 1.3}}]
    elif kind == "spin":
        anim.append({"target": "root", "spin": {"axis": [0, 1, 0], "speed": 400}})
    elif kind == "hang":     # hanging down, the root swinging sideways
        parts[0]["chain"]["direction"] = [0, -1, 0]
        anim.append({"target": "root", "oscillate": {"property": "position", "axis": [1, 0, 0], "amplitude": 0.3,
                                                     "frequency": 1.2}})
    elif kind == "flip":     # hanging down, the root turned upside down over the first 0.3 s
        parts[0]["chain"]["direction"] = [0, -1, 0]
        anim.append({"target": "root", "keyframes": {"keys": [{"time": 0, "euler": [0, 0, 0]},
                                                              {"time": 0.3, "euler": [0, 0, 150]}]}})
    elif kind == "animated":  # the chain's own bones are animated
        anim += [{"target": "tail_1", "oscillate": {"property": "rotation", "axis": [1, 0, 0], "amplitude": 40, "frequency": 1.0}},
                 {"target": "tail_3", "oscillate": {"property": "rotation", "axis": [0, 1, 0], "amplitude": 40, "frequency": 1.0}},
                 {"target": "root", "oscillate": {"property": "position", "axis": [1, 0, 0], "amplitude": 0.2, "frequency": 1.2}}]
    elif kind in ("collide", "capsule", "plane"):
        if kind == "collide":
            colliders.append({"name": "ball", "position": BALL.tolist(), "sphere": {"radius": 0.12}})
        elif kind == "capsule":
            colliders.append({"name": "ball", "position": BALL.tolist(),
                              "capsule": {"radius": 0.08, "end_radius": 0.04, "length": 0.6, "direction": "x"}})
        else:
            colliders.append({"name": "ball", "position": [0, 0.65, 0], "plane": {}})
        anim.append({"target": "root", "oscillate": {"property": "position", "axis": [1, 0, 0], "amplitude": 0.15,
                                                     "frequency": 0.8}})
        cloth["colliders"] = ["ball"]
    elif kind in ("teleport", "teleport_rot"):
        pose = {"position": [0.7, 1, 0]} if kind == "teleport" else {"euler": [0, 120, 0]}
        anim.append({"at": 0.5, "teleport": {"target": "root", **pose}})
    elif kind == "culling":  # a "camera" 8 m away
        bones.append({"name": "camera", "position": [0, 1, 8]})
        anim.append({"target": "root", "oscillate": {"property": "position", "axis": [1, 0, 0], "amplitude": 0.3,
                                                     "frequency": 1.2}})
    elif kind == "wind":
        wind = [wind_zone]
    elif kind == "wind_lines":  # a sheet: four root lines
        parts = [{"sheet": {"name": "cape", "parent": "root", "strands": 4, "bones": 4, "length": 0.5, "width": 0.4}}]
        cloth = {"name": "tail", "root_bones": ["cape_*_0"], "connection": "sequential_non_loop_mesh"}
        wind = [wind_zone]
    elif kind == "mesh":
        parts = [{"skirt": {"name": "skirt", "parent": "root", "strands": 8, "bones": 4, "radius": 0.15,
                            "length": 0.4, "flare": 20}}]
        cloth = {"name": "tail", "root_bones": ["skirt_*_0"], "connection": "sequential_loop_mesh"}
        anim += [{"target": "root", "oscillate": {"property": "rotation", "axis": [0, 0, 1], "amplitude": 40, "frequency": 1.5}},
                 {"target": "root", "oscillate": {"property": "position", "axis": [1, 0, 0], "amplitude": 0.2, "frequency": 1.1}}]
    elif kind != "still":
        raise ValueError(kind)
    cloth["parameters"] = dict(params or {})
    doc = {"version": 1, "scene": {"name": kind, "fps": 60, "frames": FRAMES, "simulation_frequency": 90},
           "rigs": [{"name": "r", "bones": bones, "parts": parts}], "cloths": [cloth]}
    if anim:
        doc["animation"] = anim
    if colliders:
        doc["colliders"] = colliders
    if wind:
        doc["wind"] = wind
    return doc


@functools.lru_cache(maxsize=None)
def _simulate(text: str):
    r = magica_py.simulate(text)
    track = r.cloths["tail"]
    return track.positions, track.rotations, r


def run(doc: dict):
    """(positions (F, N, 3), rotations (F, N, 4), Simulation) of a scene document."""
    return _simulate(yaml.safe_dump(doc, sort_keys=False))


# ----------------------------------------------------------------------------- metrics
# metric(run, animated_run) -> float; animated_run is the same scene at blend_weight 0
def tip_y(a, _anim):
    return a[0][-20:, -1, 1].mean()


def tip_x(a, _anim):
    return a[0][-20:, -1, 0].mean()


def deviation(a, anim):
    """Mean distance of the particles from the animated pose over the last 40 frames."""
    return np.linalg.norm(a[0][-40:] - anim[0][-40:], axis=-1).mean()


def rotation_deviation(a, anim):
    """Mean |1 - |q . q_anim|| of the bones over the last 40 frames (positions are not used)."""
    return (1.0 - np.abs(np.sum(a[1][-40:] * anim[1][-40:], axis=-1))).mean()


def path_length(a, _anim):
    return np.linalg.norm(np.diff(a[0], axis=0), axis=-1).sum()


def max_speed(a, _anim):
    return np.nanmax(a[2].metrics["max_speed"])


def stretch(a, _anim):
    return np.nanmax(a[2].metrics["max_edge_stretch"][5:])


def root_stretch(a, _anim):
    """Largest stretch of the root-to-tip distance (a chain of 0.6 m)."""
    p = a[0][5:]
    return (np.linalg.norm(p[:, -1] - p[:, 0], axis=-1) / 0.6 - 1.0).max()


def ball_clearance(a, _anim):
    return np.linalg.norm(a[0][-30:] - BALL, axis=-1).min()


def lowest(a, _anim):
    return a[0][-30:, :, 1].min()


def radial(a, _anim):
    return np.hypot(a[0][-20:, -1, 0], a[0][-20:, -1, 2]).mean()


# ----------------------------------------------------------------------------- the table
class Case:
    def __init__(self, scene, value, metric=None, sign=0, base=None, edit=None):
        self.scene, self.value, self.metric, self.sign = scene, value, metric, sign
        self.base = dict(base or {})
        self.edit = edit    # edit(doc) applied to both runs (scene settings the case needs)

    def docs(self, key):
        d0 = scene(self.scene, self.base)
        d1 = scene(self.scene, {**self.base, key: self.value})
        da = scene(self.scene, {**self.base, "blend_weight": 0.0})
        if self.edit:
            for d in (d0, d1, da):
                self.edit(d)
        return d0, d1, da


def _scene_set(**values):
    def edit(doc):
        doc["scene"].update(values)
    return edit


NO_GRAVITY = {"gravity": 0.0}          # the felt motion alone (inertia)
SETTLED = {"damping": 0.5}             # a still chain settling under gravity
LIMIT_10 = {"angle_limit.use": True, "angle_limit.limit_angle": {"value": 10, "use_curve": False}}
BACKSTOP = {"motion.backstop_radius": 0.5, "motion.backstop_distance": 0.05}
TETHER = {"distance.stiffness": 0.3, "solver.inextensibility": "tether"}

CASES = {
    "rotational_interpolation": Case("swing", 0.0),           # rotations only
    "root_rotation": Case("swing", 1.0),                      # rotations only
    "update_mode": Case("swing", "unscaled", edit=_scene_set(time_scale=0.5)),
    "animation_pose_ratio": Case("animated", 1.0, deviation, -1),
    "normal_axis": Case("hang", "forward", base={"motion.use_backstop": True, **BACKSTOP}),
    "gravity": Case("still", 15.0, tip_y, -1, base=SETTLED),
    "gravity_direction": Case("still", [1, 0, 0], tip_x, +1),
    "gravity_falloff": Case("still", 1.0, tip_y, +1),
    "stabilization_time_after_reset": Case("swing", 1.0),
    "blend_weight": Case("swing", 0.3, deviation, -1),
    "damping": Case("still", 0.8, path_length, -1),
    "radius": Case("collide", 0.08, ball_clearance, +1),
    "inertia.anchor": Case("swing", "root", deviation, -1, base=NO_GRAVITY),
    "inertia.anchor_inertia": Case("swing", 1.0, deviation, +1, base={**NO_GRAVITY, "inertia.anchor": "root"}),
    "inertia.world_inertia": Case("swing", 0.0, deviation, -1, base=NO_GRAVITY),
    "inertia.movement_inertia_smoothing": Case("swing", 0.95),
    "inertia.movement_speed_limit": Case("hang", 0.3, deviation, -1),
    "inertia.rotation_speed_limit": Case("spin", 30.0, deviation, -1, base=NO_GRAVITY),
    "inertia.local_inertia": Case("hang", 0.0, deviation, -1),
    "inertia.local_movement_speed_limit": Case("hang", 0.2, deviation, -1),
    "inertia.local_rotation_speed_limit": Case("spin", 20.0, deviation, -1, base=NO_GRAVITY),
    "inertia.depth_inertia": Case("hang", 1.0, deviation, -1),
    "inertia.centrifugal_acceleration": Case("spin", 1.0, radial, +1),
    "inertia.particle_speed_limit": Case("swing", 0.3, max_speed, -1),
    "inertia.teleport_mode": Case("teleport", "reset"),
    "inertia.teleport_distance": Case("teleport", 5.0, base={"inertia.teleport_mode": "reset"}),
    "inertia.teleport_rotation": Case("teleport_rot", 180.0, base={"inertia.teleport_mode": "reset"}),
    "tether.distance_compression": Case("hang", 0.0, base={"distance.stiffness": 0.05}),
    "distance.stiffness": Case("swing", 0.05, stretch, +1),
    "triangle_bending.stiffness": Case("mesh", 0.0),          # mesh connection modes only
    "angle_restoration.use": Case("swing", False, deviation, +1, base=NO_GRAVITY),
    "angle_restoration.stiffness": Case("swing", 1.0, deviation, -1),
    "angle_restoration.velocity_attenuation": Case("swing", 0.0),
    # no effect while the build orientation is kept (the "hang" scene); weaker restoration upside down
    "angle_restoration.gravity_falloff": Case("flip", 1.0, deviation, +1),
    "angle_limit.use": Case("swing", True, deviation, -1, base={"angle_limit.limit_angle": {"value": 10, "use_curve": False}}),
    "angle_limit.limit_angle": Case("swing", {"value": 5, "use_curve": False}, deviation, -1, base={"angle_limit.use": True}),
    "angle_limit.stiffness": Case("swing", 0.1, deviation, +1, base=LIMIT_10),
    "motion.use_max_distance": Case("swing", True, deviation, -1, base={"motion.max_distance": 0.05}),
    "motion.max_distance": Case("swing", 0.02, deviation, -1, base={"motion.use_max_distance": True}),
    "motion.use_backstop": Case("hang", True, base=BACKSTOP),
    "motion.backstop_radius": Case("hang", 0.1, base={"motion.use_backstop": True, "motion.backstop_distance": 0.05}),
    "motion.backstop_distance": Case("hang", 0.3, base={"motion.use_backstop": True, "motion.backstop_radius": 0.5}),
    "motion.stiffness": Case("swing", 0.1, deviation, +1, base={"motion.use_max_distance": True, "motion.max_distance": 0.02}),
    "collider_collision.mode": Case("collide", "none", ball_clearance, -1),
    "collider_collision.friction": Case("collide", 0.5),
    # a culled cloth's bones keep the animated pose: compared by rotations (see the note on positions)
    "culling.distance_culling_length": Case("culling", 2.0, rotation_deviation, -1,
                                            base={"culling.distance_culling_reference": "camera"}),
    "culling.distance_culling_fade_ratio": Case("culling", 0.9, base={"culling.distance_culling_reference": "camera",
                                                                      "culling.distance_culling_length": 8.3}),
    "culling.distance_culling_reference": Case("culling", "camera", rotation_deviation, -1,
                                               base={"culling.distance_culling_length": 2.0}),
    "wind.influence": Case("wind", 2.0, tip_x, +1),
    "wind.frequency": Case("wind", 2.0),
    "wind.turbulence": Case("wind", 0.0),
    "wind.blend": Case("wind", 0.0),
    "wind.synchronization": Case("wind_lines", 0.0),
    "wind.depth_weight": Case("wind", 1.0),
    "wind.moving_wind": Case("swing", 5.0),                   # works without a wind zone
    "solver.rate_mode": Case("swing", "frequency_consistent", edit=_scene_set(simulation_frequency=60)),
    "solver.mode": Case("swing", "quality"),
    "solver.time_based_smoothing": Case("swing", "enabled"),
    "solver.inextensibility": Case("swing", "tether", root_stretch, -1, base={"distance.stiffness": 0.3}),
    "solver.tether_limit": Case("swing", 0.1, root_stretch, +1, base=TETHER),
    "solver.distance_iterations": Case("swing", 8, stretch, -1, base={"distance.stiffness": 0.3,
                                                                        "solver.inextensibility": "iterations"}),
    "solver.ftl_damping": Case("swing", 0.0, base={"solver.inextensibility": "ftl"}),
    "solver.restoration_drift": Case("swing", "enabled", base={"solver.inextensibility": "ftl"}),
    "solver.distance_velocity": Case("swing", "full"),
    "solver.contact_speed_limit": Case("collide", 0.05, base={"solver.mode": "quality"}),
    "solver.collision_last": Case("collide", "enabled"),
}


def _changed(a, b) -> float:
    return max(np.abs(a[0][-1] - b[0][-1]).max(), np.abs(a[1][-1] - b[1][-1]).max())


def _check(d0, d1, da, metric, sign, what):
    a, b = run(d0), run(d1)
    assert np.isfinite(b[0]).all() and np.isfinite(b[1]).all(), f"{what}: non-finite output"
    assert _changed(a, b) > 1e-5, f"{what}: no effect on the final positions or rotations"
    if metric is not None and sign:
        anim = run(da)
        ma, mb = metric(a, anim), metric(b, anim)
        assert np.sign(mb - ma) == sign, (
            f"{what}: {metric.__name__} went from {ma:.4g} to {mb:.4g}, expected it to "
            f"{'grow' if sign > 0 else 'shrink'}")


@pytest.mark.parametrize("key", [d.key for d in PARAMETER_DEFS])
def test_parameter_takes_effect(key):
    assert key in CASES, f"parameter {key!r} has no case in tests/test_parameters_take_effect.py: add one"
    case = CASES[key]
    assert case.value != default_parameters()[key]
    _check(*case.docs(key), case.metric, case.sign, f"{key}={case.value!r} in scene {case.scene!r}")


def test_cases_name_only_parameters_of_the_table():
    assert set(CASES) <= {d.key for d in PARAMETER_DEFS}


# ----------------------------------------------------------------------------- validation
def _bad_values(d):
    if d.kind in ("float", "curve", "limit"):
        out = [d.hi + max(1.0, abs(d.hi))]
        if d.key in INTEGER_PARAMETERS:      # validated, not a traceback when the solver reads it
            out.append(d.lo + 0.5)
        if d.lo is not None:
            out.append(d.lo - 1.0)
        return out + ["much"]
    return {"enum": ["bogus", 3], "bool": ["sometimes", 1], "vector3": [[1, 2], ["a", 0, 0]],
            "transform": ["no_such_bone", 5]}[d.kind]


@pytest.mark.parametrize("key", [d.key for d in PARAMETER_DEFS])
def test_bad_parameter_values_are_rejected_naming_the_path(key):
    d = next(d for d in PARAMETER_DEFS if d.key == key)
    for bad in _bad_values(d):
        doc = scene("still", {key: bad})
        with pytest.raises(magica_py.ConfigError) as e:
            magica_py.simulate(yaml.safe_dump(doc, sort_keys=False), frames=1)
        paths = e.value.paths()
        assert any(p.startswith(f"cloths[0].parameters.{key}") for p in paths), (bad, paths, str(e.value))
        assert "Traceback" not in str(e.value)


def test_the_same_run_twice_gives_the_same_bits():
    doc = scene("collide", {"damping": {"value": 0.3, "curve": [1, 0.2]}, "inertia.centrifugal_acceleration": 0.5,
                            "angle_limit.use": True, "wind.moving_wind": 2.0, "solver.mode": "quality"})
    text = yaml.safe_dump(doc, sort_keys=False)
    a, b = magica_py.simulate(text), magica_py.simulate(text)
    t1, t2 = a.cloths["tail"], b.cloths["tail"]
    assert np.array_equal(t1.positions, t2.positions) and np.array_equal(t1.rotations, t2.rotations)


# ----------------------------------------------------------------------------- sub-fields
def _set(path, value):
    """edit(doc): set a nested key; path items are dict keys or list indices."""
    def edit(doc):
        node = doc
        for part in path[:-1]:
            node = node[part]
        node[path[-1]] = value
    return edit


def _param(key, value):
    return _set(("cloths", 0, "parameters", key), value)


def _zone(**values):
    def edit(doc):
        doc["wind"][0].update(values)
    return edit


def _radial(doc):
    doc["wind"][0].pop("direction")
    doc["wind"][0].update(mode="radial", position=[-0.5, 1, -0.3], radius=2.0)


SUB_CASES = {
    # curves: the shape over depth, and the three ways of writing one
    "curve.shape": ("swing", {"damping": {"value": 0.5, "use_curve": False}},
                    _param("damping", {"value": 0.5, "curve": [1.0, 0.0]}), None, 0),
    "curve.keys": ("swing", {"angle_restoration.stiffness": {"value": 0.5, "use_curve": False}},
                   _param("angle_restoration.stiffness", {"value": 0.5, "keys": [[0, 0, 0, 0], [1, 1, 0, 0]]}), None, 0),
    "curve.bare_number_scales_the_shape": ("swing", {}, _param("angle_restoration.stiffness", 0.6), deviation, -1),
    "limit.mapping": ("swing", {}, _param("inertia.particle_speed_limit", {"use": True, "value": 0.3}), max_speed, -1),
    "limit.off": ("swing", {}, _param("inertia.particle_speed_limit", False), max_speed, +1),
    # colliders
    "collider.sphere.radius": ("collide", {}, _set(("colliders", 0, "sphere", "radius"), 0.2), ball_clearance, +1),
    "collider.capsule.radius": ("capsule", {}, _set(("colliders", 0, "capsule", "radius"), 0.15), None, 0),
    "collider.capsule.end_radius": ("capsule", {}, _set(("colliders", 0, "capsule", "end_radius"), 0.15), None, 0),
    "collider.capsule.length": ("capsule", {}, _set(("colliders", 0, "capsule", "length"), 0.1), None, 0),
    "collider.capsule.direction": ("capsule", {}, _set(("colliders", 0, "capsule", "direction"), "z"), None, 0),
    "collider.capsule.reverse": ("capsule", {}, _set(("colliders", 0, "capsule", "reverse"), True), None, 0),
    "collider.capsule.aligned_on_center": ("capsule", {}, _set(("colliders", 0, "capsule", "aligned_on_center"), False), None, 0),
    "collider.plane.position": ("plane", {}, _set(("colliders", 0, "position"), [0, 0.8, 0]), lowest, +1),
    "collider.edge_mode": ("collide", {}, _set(("cloths", 0, "collision_mode"), "edge"), None, 0),
    # wind zones
    "wind.main": ("wind", {}, _zone(main=10.0), tip_x, +1),
    "wind.zone_turbulence": ("wind", {}, _zone(turbulence=0.0), None, 0),
    "wind.direction": ("wind", {}, _zone(direction=[0, 0, 1]), tip_x, -1),
    "wind.direction_angles": ("wind", {}, lambda d: (d["wind"][0].pop("direction"),
                                                     d["wind"][0].update(direction_angles=[0, -90])), tip_x, -1),
    "wind.enabled": ("wind", {}, _zone(enabled=False), tip_x, -1),
    "wind.sphere_outside": ("wind", {}, _zone(mode="sphere", position=[5, 5, 5], radius=1.0), tip_x, -1),
    "wind.box_outside": ("wind", {}, _zone(mode="box", size=[0.1, 0.1, 0.1], position=[0, 1.2, 0]), tip_x, -1),
    "wind.radial": ("wind", {}, _radial, None, 0),
    "wind.radial_attenuation": ("wind", {}, lambda d: (_radial(d), d["wind"][0].update(attenuation={"value": 1, "curve": [1, 1]})), None, 0),
    # timing
    "scene.simulation_frequency": ("swing", {}, _scene_set(simulation_frequency=60), None, 0),
    "scene.max_steps_per_frame": ("swing", {}, lambda d: d["scene"].update(fps=20, frames=20, max_steps_per_frame=1), None, 0),
    "scene.timing": ("swing", {}, lambda d: d["scene"].update(fps=47, timing="faithful32"), None, 0),
    "scene.global_time_scale": ("swing", {}, _scene_set(global_time_scale=0.5), None, 0),
    "scene.time_scale": ("swing", {}, _scene_set(time_scale=0.5), None, 0),
    "scene.update_mode": ("swing", {}, lambda d: d["scene"].update(update_mode="unscaled", time_scale=0.5), None, 0),
    "scene.fixed_delta_time": ("swing", {"update_mode": "unity_physics"}, _scene_set(fixed_delta_time=0.05), None, 0),
    "scene.maximum_delta_time": ("swing", {}, lambda d: d["scene"].update(frame_times=[0.016, 0.2], fps=None,
                                                                          maximum_delta_time=0.05), None, 0),
    "scene.gravity": ("still", {}, _scene_set(gravity=[1, 0, 0]), tip_x, +1),
}


@pytest.mark.parametrize("name", sorted(SUB_CASES))
def test_setting_takes_effect(name):
    kind, base, edit, metric, sign = SUB_CASES[name]
    d0, da = scene(kind, base), scene(kind, {**base, "blend_weight": 0.0})
    d1 = copy.deepcopy(d0)
    edit(d1)
    if name == "scene.maximum_delta_time":      # the same frame times in the default run
        for d in (d0, da):
            d["scene"].update(frame_times=[0.016, 0.2], fps=None)
    for d in (d0, d1, da):
        if d["scene"].get("fps", 0) is None:
            del d["scene"]["fps"]
    _check(d0, d1, da, metric, sign, name)


def test_a_culled_cloth_reports_its_bones_positions_not_the_origin():
    """A cloth culled from its first frame is never simulated and its bones keep the animated
    pose (docs/solver.md §H.1): its display positions, the recording's particles and the
    stretch metric must show those bones, not particles at the world origin with 100 %
    stretch (found by this file: the culling cases read zeros)."""
    doc = scene("culling", {"culling.distance_culling_reference": "camera", "culling.distance_culling_length": 2.0})
    animated = run(scene("culling", {"culling.distance_culling_reference": "camera", "blend_weight": 0.0}))
    culled = run(doc)
    assert culled[2].metrics["cloth.simulation_steps"][-1] == 0 or np.isnan(culled[2].metrics["cloth.simulation_steps"][-1])
    np.testing.assert_allclose(culled[0], animated[0], atol=1e-9)
    assert np.nanmax(culled[2].metrics["max_edge_stretch"]) < 1e-6
    with magica_py.Session(yaml.safe_dump(doc, sort_keys=False)) as session:
        for _ in range(5):
            session.step()
        h = session.scene.hierarchy
        bones = h.world_position[[h.index(f"tail_{i}") for i in range(6)]]
        np.testing.assert_allclose(session.system.positions("tail"), bones, atol=1e-12)
