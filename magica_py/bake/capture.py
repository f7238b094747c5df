"""Capture the simulated local poses of chosen bones, one key per rendered frame.

``PoseCapture`` is a RENDER_WRITE system: after the cloth has written its bones back
(LATE_UPDATE) it copies the local pose of every captured bone into preallocated arrays.
``select_bones`` chooses the bones (every bone of the scene's rigs, or those matching globs).
``simulate_and_capture`` runs a scene the way ``magica-py run`` does (player + cloth solver)
with a capture attached.

Arrays of a finished capture (F frames, B bones, Unity convention, metres, seconds):

==================  ==========  =====================================================
times               (F,)        unscaled time of each rendered frame, first frame = 0
local_position      (F, B, 3)   m, local position after the cloth write-back
local_rotation      (F, B, 4)   xyzw, same, sign-continuous over frames per bone
local_scale         (F, B, 3)   local scale
==================  ==========  =====================================================
"""
from __future__ import annotations

import fnmatch
from dataclasses import dataclass, field

import numpy as np


@dataclass
class CapturedMotion:
    """What a capture recorded (see the module docstring for the arrays)."""

    bones: np.ndarray                 # (B,) int32 hierarchy indices, parents before children
    names: list[str]                  # (B,) bone names
    parent: np.ndarray                # (B,) int32 index into ``bones`` of the parent, -1 if not captured
    rest_position: np.ndarray         # (B, 3) m, rest local pose (hierarchy.rest_local_*)
    rest_rotation: np.ndarray         # (B, 4)
    rest_scale: np.ndarray            # (B, 3)
    times: np.ndarray
    local_position: np.ndarray
    local_rotation: np.ndarray
    local_scale: np.ndarray
    frame_times: np.ndarray           # (F,) s, unscaled delta time of each frame
    wall_time: float = 0.0            # s, simulation loop
    notes: list[str] = field(default_factory=list)

    @property
    def frames(self) -> int:
        return int(self.times.shape[0])


def rig_bones(scene) -> list[int]:
    """Hierarchy indices of every bone of the scene's rigs, parents before children: every
    transform but the static nodes the loader adds for colliders without a transform
    (tagged ``collider``). A rig may have several roots (a glTF scene often has)."""
    h = scene.hierarchy
    tags = getattr(h, "tags", None) or [{}] * h.count
    return [i for i in range(h.count) if "collider" not in tags[i]]


def select_bones(scene, patterns=None) -> list[int]:
    """Bones to bake: every rig bone, or the rig bones matching any glob of ``patterns``.
    Raises ``ValueError`` naming the globs that match nothing."""
    bones = rig_bones(scene)
    if not patterns:
        return bones
    names = scene.hierarchy.names
    unmatched = [p for p in patterns if not any(fnmatch.fnmatchcase(names[i], p) for i in bones)]
    if unmatched:
        raise ValueError(f"--bones {', '.join(map(repr, unmatched))} matches no bone of the scene's rigs")
    return [i for i in bones if any(fnmatch.fnmatchcase(names[i], p) for p in patterns)]


class PoseCapture:
    """RENDER_WRITE system copying the local poses of ``bones`` each frame (no allocation
    in the frame: arrays are sized for ``frames`` up front)."""

    name = "bake_capture"

    def __init__(self, hierarchy, bones, frames: int):
        self.hierarchy = hierarchy
        self.bones = np.asarray(bones, dtype=np.int64)
        b = self.bones.shape[0]
        self.capacity = int(frames)
        self.count = 0
        self.times = np.zeros(frames)
        self.frame_times = np.zeros(frames)
        self.local_position = np.zeros((frames, b, 3))
        self.local_rotation = np.zeros((frames, b, 4))
        self.local_scale = np.zeros((frames, b, 3))

    def attach(self, player) -> "PoseCapture":
        from magica_py.runtime.phases import Phase, System

        player.schedule.add(Phase.RENDER_WRITE, System(self.name, self.run))
        return self

    def run(self, ctx) -> None:
        k = self.count
        if k >= self.capacity:
            raise RuntimeError(f"pose capture sized for {self.capacity} frames received frame {k + 1}")
        h = self.hierarchy
        self.times[k] = ctx.time.unscaled_time
        self.frame_times[k] = ctx.time.unscaled_delta_time
        np.take(h.local_position, self.bones, axis=0, out=self.local_position[k])
        np.take(h.local_rotation, self.bones, axis=0, out=self.local_rotation[k])
        np.take(h.local_scale, self.bones, axis=0, out=self.local_scale[k])
        self.count = k + 1

    def result(self, wall_time: float = 0.0) -> CapturedMotion:
        h = self.hierarchy
        f = self.count
        index = {int(n): j for j, n in enumerate(self.bones)}
        parent = np.array([index.get(int(h.parent[n]), -1) for n in self.bones], dtype=np.int32)
        times = self.times[:f] - (self.times[0] if f else 0.0)
        rotation = continuous_quaternions(self.local_rotation[:f])
        return CapturedMotion(bones=self.bones.astype(np.int32), names=[h.names[int(n)] for n in self.bones],
                              parent=parent, rest_position=h.rest_local_position[self.bones].copy(),
                              rest_rotation=h.rest_local_rotation[self.bones].copy(),
                              rest_scale=h.rest_local_scale[self.bones].copy(), times=times,
                              local_position=self.local_position[:f].copy(), local_rotation=rotation,
                              local_scale=self.local_scale[:f].copy(), frame_times=self.frame_times[:f].copy(),
                              wall_time=wall_time)


def continuous_quaternions(q: np.ndarray) -> np.ndarray:
    """(F, B, 4) quaternions with each bone's sign chosen so consecutive keys are in the same
    hemisphere (q and -q are the same rotation; linear and slerp interpolation then take the
    short way), the first key with w >= 0."""
    out = np.array(q, dtype=np.float64, copy=True)
    if out.shape[0] == 0:
        return out
    out[0] *= np.where(out[0, :, 3:4] < 0.0, -1.0, 1.0)
    for k in range(1, out.shape[0]):
        dot = np.einsum("bi,bi->b", out[k], out[k - 1])
        out[k] *= np.where(dot < 0.0, -1.0, 1.0)[:, None]
    return out


def simulate_and_capture(scene, bones, frames: int, progress=None, compile_watch=None) -> CapturedMotion:
    """Run ``scene`` for ``frames`` frames (player, cloth solver as ``magica-py run``, no
    recording) and capture ``bones``; ``progress(done, frames)`` after each frame. The
    motion's ``wall_time`` leaves out the compiles ``compile_watch`` (a ``runner.CompileWatch``
    around the call) saw during the frames."""
    from magica_py.runner import Stopwatch
    from magica_py.runtime.player import Player

    player = Player.for_scene(scene)
    if scene.cloths:
        from magica_py.solver import attach

        attach(player, scene)
    capture = PoseCapture(scene.hierarchy, bones, frames).attach(player)
    with Stopwatch(compile_watch) as frames_time:
        for k in range(frames):
            player.step()
            if progress is not None:
                progress(k + 1, frames)
    return capture.result(frames_time.seconds)
