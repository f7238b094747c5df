"""The lane form against the team-by-team solver and a packed ceiling, on one stage (issue 15).

    python benchmarks/lane_ceiling.py [--reps 20]

This script first measured how far a *hypothetical* lane layout could take the light scene;
the solver now runs in that layout (``solver/lanes.py``), so it measures the solver's own
stage. One stage, distance (D.4: two passes a step, the light scene's largest per-step stage),
on the light scene (``configs/light_chains.yaml``, 1,000 chains of 16 particles, after 20
frames), three ways:

1. **team by team**: the per-team solver before the lane form (``tests/reference_solver``,
   frozen), its ``distance_team`` over every team, on its own run of the scene;
2. **lane form**: the solver's ``distance_block`` over every block (teams of one structure
   side by side, one per lane), as ``frame.run_step`` calls it. Both runs are checked to hold
   the same bits before the pass and after it (team-ordered ``next_pos`` and ``velocity_pos``);
3. **packed ceiling**: a reduced distance pass (parent and child link, depth masses, 30 % of
   the correction into ``velocity_pos``; no stiffness curve, friction, rest-length blend or
   zero-distance links: less work than the solver's) over a packed array ``S[row, j, lane]``,
   written out in one loop body (and through a per-link helper): what the arithmetic alone
   costs when the lane loop vectorises.

For each: time per pass over the 16,000 particles, ns per particle, and the number of packed
ymm / zmm arithmetic instructions in its machine code (0: the loops stayed scalar). The light
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
sys.path.insert(0, str(ROOT / "tests"))

from magica_py.jit import JIT_OPTIONS  # noqa: E402
from magica_py.solver.attenuations import step_attenuations  # noqa: E402
from magica_py.solver.constraints.distance import distance_block  # noqa: E402

OPTIONS = dict(JIT_OPTIONS, cache=False)
NX, VPX, REST, DEPTH, ROWS = 0, 3, 6, 7, 8      # packed rows: next_pos, velocity_pos, rest, depth


def reference_pass():
    """The per-team solver's pass over every team (compiled on first use)."""
    from reference_solver.solver.constraints.distance import distance_team

    @numba.njit(**OPTIONS)
    def teams_in_turn(m, ps, prm, ts, live):
        for t in live:
            distance_team(m, ps, prm, ts, t, 1.0, 1.0, 0.3)

    return teams_in_turn, distance_team


@numba.njit(**OPTIONS)
def blocks_in_turn(T):
    """``distance_block`` over every block, with the step's attenuation as ``run_step`` takes it."""
    for i in range(T.blocks.shape[0]):
        b = T.blocks[i]
        _tether, distance, _limit, _restoration, _motion = step_attenuations(T.P, b, 1.0)
        distance_block(T.PS, T.PM, T.PP, T.TS, T.TM, T.LM, T.P, T.BI, T.topology, b, 1.0, 1.0, distance)


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
    """Packed ymm / zmm arithmetic instructions in ``fn``'s machine code for the signatures it
    was called with. A kernel loaded from numba's cache has no code to inspect: its Python
    function is compiled again (no cache) for the same signatures and that code is counted
    (the callees it inlines included, those it calls not)."""
    def asm_of(dispatcher):
        return "\n".join(dispatcher.inspect_asm(sig) for sig in dispatcher.signatures)

    if getattr(fn, "_cache_hits", None) and sum(fn._cache_hits.values()):
        options = {k: v for k, v in fn.targetoptions.items() if k != "nopython"}
        fresh = numba.njit(**options)(fn.py_func)
        for sig in fn.signatures:
            fresh.compile(sig)
        fn = fresh
    return len(re.findall(r"\bv(?:sqrt|div|mul|add|sub|fmadd\w*|fnmadd\w*)pd\s+[^\n]*%[yz]mm", asm_of(fn)))


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
    ap.add_argument("--scene", default="light_chains")
    ap.add_argument("--frames", type=int, default=20)
    args = ap.parse_args(argv)
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver.system import ClothSystem
    from reference_solver.solver.system import ClothSystem as ReferenceSystem

    def run(cls):
        scene = load_scene(ROOT / "configs" / f"{args.scene}.yaml")
        player = Player.for_scene(scene)
        system = cls(scene.hierarchy, scene.cloths, scene.colliders, scene.settings, parallel=False).attach(player)
        player.run(args.frames)
        return system

    lanes, ref = run(ClothSystem), run(ReferenceSystem)
    T = lanes.tables
    m, ps, prm, ts, _cs, _tt, _h = ref.kernel_tables()
    live = ref.model.live_teams
    teams_in_turn, distance_team = reference_pass()

    def state(system):
        return system.particles.next_pos, system.particles.velocity_pos

    same_before = all(np.array_equal(a, b) for a, b in zip(state(lanes), state(ref)))
    saved_ps = T.PS.copy()
    saved_ref = [a.copy() for a in (ref.particles.next_pos, ref.particles.velocity_pos)]

    def reset_lanes():
        T.PS[:] = saved_ps

    def reset_ref():
        for a, s in zip((ref.particles.next_pos, ref.particles.velocity_pos), saved_ref):
            a[:] = s

    blocks_in_turn(T)
    teams_in_turn(m, ps, prm, ts, live)
    same_after = all(np.array_equal(a, b) for a, b in zip(state(lanes), state(ref)))
    reset_lanes()
    reset_ref()

    n = int(lanes.model.team_particle_count.sum())
    chains, per = len(live), n // max(len(live), 1)
    S0 = np.zeros((ROWS, per, chains))
    S0[NX:NX + 3] = lanes.particles.next_pos.T.reshape(3, chains, per).transpose(0, 2, 1)
    S0[VPX:VPX + 3] = S0[NX:NX + 3]
    S0[REST] = 0.05
    S0[DEPTH] = (np.arange(per) / (per - 1))[:, None]
    S = S0.copy()

    def reset_packed():
        S[:] = S0

    rows = [("team by team (per-team solver)", lambda: teams_in_turn(m, ps, prm, ts, live), reset_ref, distance_team),
            ("lane form (distance_block)", lambda: blocks_in_turn(T), reset_lanes, distance_block),
            ("packed ceiling, per-link helper", lambda: packed_helpers(S), reset_packed, packed_helpers),
            ("packed ceiling, one loop body", lambda: packed_one_body(S), reset_packed, packed_one_body)]
    load = pathlib.Path("/proc/loadavg").read_text().split()[0]
    print(f"distance pass over {n} particles ({chains} chains in {T.blocks.shape[0]} blocks); min of {args.reps}; "
          f"load {load}")
    for name, fn, rs, kern in rows:
        t = best_of(fn, rs, args.reps)
        print(f"  {name:32s} {t * 1e6:8.1f} us  {t / n * 1e9:6.2f} ns/particle  packed ops {packed_ops(kern)}")
    print(f"the lane form holds the per-team solver's bits: before the pass {same_before}, after it {same_after}")
    return 0 if same_before and same_after else 1


if __name__ == "__main__":
    raise SystemExit(main())
