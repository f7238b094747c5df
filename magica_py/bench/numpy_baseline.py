"""The single-tail step as a user would write it without magica_py: plain vectorised numpy.

A position-based chain in the spirit of MagicaCloth2's BoneCloth, written the way one
writes it in an afternoon: fixed 90 Hz steps with a time accumulator, the chain's rest
shape carried by the animated root (the base pose), damping, gravity, prediction, a tether
to the root, two Jacobi passes of distance constraints, angle restoration towards the
base pose, velocity from the position change and a particle speed limit. Everything is
numpy over the particles of the chain; the loop over steps and constraint passes is
Python. It exists to measure the speed ratio side by side (``magica-py bench``), not to be
accurate: its error against the converged reference is reported, not tuned.

State (all (N,3) float64, world space, m and m/s): ``position``, ``velocity``; the rest
offsets ``rest_offset`` (N,3) are in the root's frame, taken from the build pose.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numpy as np


def _rotation_matrix(q) -> np.ndarray:
    x, y, z, w = (float(c) for c in q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@dataclass
class NumpyChain:
    """A chain of particles hanging from particle 0 (fixed, follows the root bone)."""

    rest_offset: np.ndarray        # (N,3) m, rest positions in the root's frame
    parent: np.ndarray             # (N,) int, -1 for the root
    position: np.ndarray           # (N,3) m
    velocity: np.ndarray           # (N,3) m/s
    gravity: float = 2.0           # m/s^2 (the tail_orbit scene's value)
    gravity_direction: tuple = (0.0, -1.0, 0.0)
    damping: float = 0.01          # per step at 90 Hz (0.05 x 0.2 as in docs/solver.md §F.1)
    restoration: float = 0.02      # per step, pull towards the base pose (0.1 x 0.2)
    tether_limit: float = 1.03     # max root distance / rest
    speed_limit: float = 4.0       # m/s
    frequency: int = 90
    accumulator: float = 0.0

    @classmethod
    def from_rest(cls, rest_world: np.ndarray, parent: np.ndarray, root_position, root_rotation, **kw):
        r = _rotation_matrix(root_rotation)
        offset = (np.asarray(rest_world) - np.asarray(root_position)) @ r   # world -> root frame
        return cls(offset, np.asarray(parent), np.array(rest_world, dtype=np.float64),
                   np.zeros_like(rest_world, dtype=np.float64), **kw)

    def frame(self, dt: float, root_position, root_rotation, old_root_position, old_root_rotation) -> None:
        """Advance one rendered frame of ``dt`` seconds; the root moves linearly between
        the old and new pose over the steps of the frame."""
        h = 1.0 / self.frequency
        self.accumulator += dt
        steps = int(self.accumulator / h + 1e-9)
        self.accumulator -= steps * h
        if steps == 0:
            return
        p0, p1 = np.asarray(old_root_position), np.asarray(root_position)
        r0, r1 = _rotation_matrix(old_root_rotation), _rotation_matrix(root_rotation)
        child = np.nonzero(self.parent >= 0)[0]
        par = self.parent[child]
        rest_len = np.linalg.norm(self.rest_offset[child] - self.rest_offset[par], axis=1)
        root_len = np.linalg.norm(self.rest_offset - self.rest_offset[0], axis=1)
        g = np.asarray(self.gravity_direction) * self.gravity
        for k in range(steps):
            u = (k + 1) / steps
            root = p0 + (p1 - p0) * u
            rot = r0 + (r1 - r0) * u                        # a user's nlerp of the matrix
            q, _ = np.linalg.qr(rot)
            rot = q * np.sign(np.diag(q))[None, :]
            base = root + self.rest_offset @ rot.T
            old = self.position
            v = self.velocity * (1.0 - self.damping)
            nxt = old + v * h + g * (h * h)
            nxt[0] = base[0]
            # tether to the root
            d = nxt - nxt[0]
            dist = np.linalg.norm(d, axis=1)
            over = dist > root_len * self.tether_limit
            if over.any():
                nxt[over] = nxt[0] + d[over] * (root_len[over] * self.tether_limit / dist[over])[:, None]
            # distance constraints, Jacobi, two passes
            for _ in range(2):
                e = nxt[child] - nxt[par]
                length = np.maximum(np.linalg.norm(e, axis=1), 1e-12)
                corr = e * ((length - rest_len) / length)[:, None]
                w_child = np.where(par == 0, 1.0, 0.5)[:, None]
                delta = np.zeros_like(nxt)
                np.add.at(delta, child, -corr * w_child)
                np.add.at(delta, par, corr * (1.0 - w_child))
                delta[0] = 0.0
                nxt += delta
            # angle restoration: each edge towards the base pose's edge
            target = nxt[par] + (base[child] - base[par])
            nxt[child] += (target - nxt[child]) * self.restoration
            vel = (nxt - old) / h
            speed = np.linalg.norm(vel, axis=1)
            fast = speed > self.speed_limit
            if fast.any():
                vel[fast] *= (self.speed_limit / speed[fast])[:, None]
            self.velocity = vel
            self.position = nxt


def run_numpy_tail(scene, frames: int, frequency: int = 90) -> dict:
    """Run the scene's first cloth (a single line chain) with ``NumpyChain`` on the animated
    root: the player runs without any cloth system (restore, animation only) and the numpy
    step follows. Returns wall times per frame (s) of the whole loop and of the numpy part,
    and the positions (F, N, 3)."""
    from magica_py.build import build_cloth
    from magica_py.runtime.player import Player

    spec = scene.cloths[0]
    model = build_cloth(scene.hierarchy, spec)
    nodes = np.asarray(model.transform_index, dtype=np.int64)
    h = scene.hierarchy
    h.propagate()
    root_node = int(nodes[0])
    params = spec.parameters
    gravity = float(params.get("gravity", 2.0))
    chain = NumpyChain.from_rest(h.world_position[nodes].copy(), np.asarray(model.parent),
                                 h.world_position[root_node].copy(), h.world_rotation[root_node].copy(),
                                 gravity=gravity, frequency=frequency)
    player = Player.for_scene(scene)
    old_p = h.world_position[root_node].copy()
    old_r = h.world_rotation[root_node].copy()
    wall = np.zeros(frames)
    numpy_wall = np.zeros(frames)
    positions = np.zeros((frames, nodes.shape[0], 3))
    clock = _time.perf_counter
    for i in range(frames):
        t0 = clock()
        ctx = player.step()
        t1 = clock()
        p = h.world_position[root_node].copy()
        r = h.world_rotation[root_node].copy()
        chain.frame(ctx.time.delta_time, p, r, old_p, old_r)
        old_p, old_r = p, r
        t2 = clock()
        wall[i] = t2 - t0
        numpy_wall[i] = t2 - t1
        positions[i] = chain.position
    return {"wall": wall, "numpy_wall": numpy_wall, "positions": positions,
            "particles": int(nodes.shape[0]), "steps_per_second": math.nan}
