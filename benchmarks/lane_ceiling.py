"""How far a lane layout could take the light scene with numba's documented features (issue 15).

    python benchmarks/lane_ceiling.py [--reps 20]

One stage, distance (D.4: two passes a step, the light scene's largest per-step stage),
measured four ways on the light scene (``configs/light_chains.yaml``, 1,000 chains of 16
particles, after 20 frames):

1. **team by team**: the solver's ``distance_team`` over every team, as the frame runs it;
2. **lane by lane, solver layout**: the same per-element code, particle j of every team side
   by side (the loop order of a lane form) on the solver's own arrays. It gives the same bits
   (checked). It answers whether the stage is latency-bound (a chain's particles depend on each
   other, independent chains side by side would overlap that latency): it is not if it is
   not faster;
3. **packed lanes, per-particle helpers**: a reduced distance pass (parent and child link,
   depth masses, 30 % of the correction into ``velocity_pos``; no stiffness curve, friction,
   rest-length blend or zero-distance links: less work than the solver's) over a packed
   array ``S[row, j, lane]`` (one base pointer: LLVM needs no alias information to vectorise
   across lanes), written through a per-link helper as the solver's stages are;
4. **packed lanes, one loop body**: the same arithmetic written out in the loop.

For each: time per pass over the 16,000 particles, ns per particle, and the number of packed
ymm / zmm arithmetic instructions in its machine code (0: the loop stayed scalar). The light
scene's kernel bound (2x numpy, about 0.4 ms a frame) is ~17 ns per particle-step for every
stage together; a step runs this stage twice.
"""
from __future__ import annotations

import argparse
import re
import sys
import time
import pathlib

import numba
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from magica_py.jit import JIT_OPTIONS  # noqa: E402
from magica_py.kernels.math3d import inverse_mass_friction_depth, load3, store3, v_add, v_scale, v_sub  # noqa: E402
from magica_py.solver.constraints.distance import (  # noqa: E402
    FIX_MASS, MOVE, ZERO3, distance_apply, distance_link, distance_rest_length, distance_stiffness, distance_team,
)

OPTIONS = dict(JIT_OPTIONS, cache=False)
NX, VPX, REST, DEPTH, ROWS = 0, 3, 6, 7, 8      # packed rows: next_pos, velocity_pos, rest, depth


@numba.njit(**OPTIONS)
def teams_in_turn(m, ps, prm, ts, live):
    for t in live:
        distance_team(m, ps, prm, ts, t, 1.0, 1.0, 0.3)


@numba.njit(**OPTIONS)
def lanes_solver_layout(m, ps, prm, ts, live):
    """``distance_team``'s body with the loops swapped: particle j of every team, then j + 1."""
    attribute, depth_of, friction = m.attribute, m.depth, ps.friction
    distance_start, distance_count, distance_target, distance_rest = (
        m.distance_start, m.distance_count, m.distance_target, m.distance_rest)
    next_pos_a, base_pos_a, velocity_pos_a = ps.next_pos, ps.base_pos, ps.velocity_pos
    tps, tpc = m.team_particle_start, m.team_particle_count
    most = 0
    for team in live:
        most = max(most, tpc[team])
    for j in range(most):
        for team in live:
            if j >= tpc[team]:
                continue
            p = tps[team] + j
            if (attribute[p] & MOVE) == 0:
                continue
            a = prm.animation_pose_ratio[team]
            s = m.team_init_scale[team, 0] * ts.scale_ratio[team]
            depth = depth_of[p]
            w_p = inverse_mass_friction_depth(friction[p], depth)
            k_vertical, k_horizontal = distance_stiffness(prm, team, depth, 1.0, 1.0)
            pp = load3(next_pos_a, p)
            bp = load3(base_pos_a, p)
            acc = ZERO3
            n = 0
            for link in range(distance_start[p], distance_start[p] + distance_count[p]):
                q = distance_target[link]
                r = distance_rest[link]
                qp = load3(next_pos_a, q)
                if r == 0.0:
                    acc = v_scale(v_sub(qp, pp), 0.5)
                    n += 1
                    continue
                w_q = 1.0 / FIX_MASS if (attribute[q] & MOVE) == 0 else inverse_mass_friction_depth(friction[q], depth_of[q])
                rest = distance_rest_length(r, s, bp, load3(base_pos_a, q), a)
                corr, ok = distance_link(pp, qp, rest, w_p, w_q, k_vertical if r > 0.0 else k_horizontal)
                if ok:
                    acc = v_add(acc, corr)
                    n += 1
            next_pos, velocity_pos = distance_apply(pp, load3(velocity_pos_a, p), acc, n, 0.3)
            store3(next_pos_a, p, next_pos)
            store3(velocity_pos_a, p, velocity_pos)


@numba.njit(**OPTIONS)
def _link(S, j, q, l, rest, w_p):
    dx = S[NX, q, l] - S[NX, j, l]
    dy = S[NX + 1, q, l] - S[NX + 1, j, l]
    dz = S[NX + 2, q, l] - S[NX + 2, j, l]
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    dq = 1.0 - S[DEPTH, q, l]
    w_q = 1.0 / (1.0 + 5.0 * dq * dq)
    s = (length - rest) * w_p / (length * (w_p + w_q))
    return dx * s, dy * s, dz * s


@numba.njit(**OPTIONS)
def packed_helpers(S):
    J, W = S.shape[1], S.shape[2]
    for j in range(1, J - 1):
        for l in range(W):
            dp = 1.0 - S[DEPTH, j, l]
            w_p = 1.0 / (1.0 + 5.0 * dp * dp)
            ax, ay, az = _link(S, j, j - 1, l, S[REST, j, l], w_p)
            bx, by, bz = _link(S, j, j + 1, l, S[REST, j + 1, l], w_p)
            ax, ay, az = (ax + bx) * 0.5, (ay + by) * 0.5, (az + bz) * 0.5
            S[NX, j, l] += ax
            S[NX + 1, j, l] += ay
            S[NX + 2, j, l] += az
            S[VPX, j, l] += 0.3 * ax
            S[VPX + 1, j, l] += 0.3 * ay
            S[VPX + 2, j, l] += 0.3 * az


@numba.njit(**OPTIONS)
def packed_one_body(S):
    J, W = S.shape[1], S.shape[2]
    for j in range(1, J - 1):
        for l in range(W):
            dp = 1.0 - S[DEPTH, j, l]
            w_p = 1.0 / (1.0 + 5.0 * dp * dp)
            dx = S[NX, j - 1, l] - S[NX, j, l]
            dy = S[NX + 1, j - 1, l] - S[NX + 1, j, l]
            dz = S[NX + 2, j - 1, l] - S[NX + 2, j, l]
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            dq = 1.0 - S[DEPTH, j - 1, l]
            s = (length - S[REST, j, l]) * w_p / (length * (w_p + 1.0 / (1.0 + 5.0 * dq * dq)))
            ax, ay, az = dx * s, dy * s, dz * s
            dx = S[NX, j + 1, l] - S[NX, j, l]
            dy = S[NX + 1, j + 1, l] - S[NX + 1, j, l]
            dz = S[NX + 2, j + 1, l] - S[NX + 2, j, l]
            length = np.sqrt(dx * dx + dy * dy + dz * dz)
            dq = 1.0 - S[DEPTH, j + 1, l]
            s = (length - S[REST, j + 1, l]) * w_p / (length * (w_p + 1.0 / (1.0 + 5.0 * dq * dq)))
            ax, ay, az = (ax + dx * s) * 0.5, (ay + dy * s) * 0.5, (az + dz * s) * 0.5
            S[NX, j, l] += ax
            S[NX + 1, j, l] += ay
            S[NX + 2, j, l] += az
            S[VPX, j, l] += 0.3 * ax
            S[VPX + 1, j, l] += 0.3 * ay
            S[VPX + 2, j, l] += 0.3 * az


def packed_ops(fn) -> int:
    asm = "\n".join(fn.inspect_asm(sig) for sig in fn.signatures)
    return len(re.findall(r"\bv(?:sqrt|div|mul|add|sub|fmadd\w*|fnmadd\w*)pd\s+[^\n]*%[yz]mm", asm))


def best_of(fn, reset, reps):
    fn()
    best = []
    for _ in range(reps):
        reset()
        t0 = time.perf_counter()
        fn()
        best.append(time.perf_counter() - t0)
    return min(best)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=20)
    args = ap.parse_args(argv)
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem

    scene = load_scene(ROOT / "configs" / "light_chains.yaml")
    player = Player.for_scene(scene)
    system = ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings, parallel=False).attach(player)
    player.run(20)
    m, ps, prm, ts, _cs, _tt, _h = system.kernel_tables()
    live = system.model.live_teams
    arrays = (system.particles.next_pos, system.particles.velocity_pos)
    saved = [a.copy() for a in arrays]

    def reset():
        for a, s in zip(arrays, saved):
            a[:] = s

    teams_in_turn(m, ps, prm, ts, live)
    by_team = [a.copy() for a in arrays]
    reset()
    lanes_solver_layout(m, ps, prm, ts, live)
    same = all(np.array_equal(a, b) for a, b in zip(arrays, by_team))
    n = int(system.model.team_particle_count.sum())
    chains, per = len(live), n // max(len(live), 1)
    S0 = np.zeros((ROWS, per, chains))
    S0[NX:NX + 3] = system.particles.next_pos.T.reshape(3, chains, per).transpose(0, 2, 1)
    S0[VPX:VPX + 3] = S0[NX:NX + 3]
    S0[REST] = 0.05
    S0[DEPTH] = (np.arange(per) / (per - 1))[:, None]
    S = S0.copy()

    def reset_packed():
        S[:] = S0

    rows = [("team by team (the solver today)", lambda: teams_in_turn(m, ps, prm, ts, live), reset, teams_in_turn),
            ("lane by lane, solver layout", lambda: lanes_solver_layout(m, ps, prm, ts, live), reset, lanes_solver_layout),
            ("packed lanes, per-link helper", lambda: packed_helpers(S), reset_packed, packed_helpers),
            ("packed lanes, one loop body", lambda: packed_one_body(S), reset_packed, packed_one_body)]
    load = pathlib.Path("/proc/loadavg").read_text().split()[0]
    print(f"distance pass over {n} particles ({chains} chains); min of {args.reps}; load {load}")
    for name, fn, rs, kern in rows:
        t = best_of(fn, rs, args.reps)
        print(f"  {name:32s} {t * 1e6:8.1f} us  {t / n * 1e9:6.2f} ns/particle  packed ops {packed_ops(kern)}")
    print(f"lane order gives the solver's bits: {same}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
