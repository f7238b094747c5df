"""Where the bench's reference residual comes from (issue 22; docs/BENCHMARKS.md, *References*).

    python benchmarks/bench_reference.py grid --scene tail_orbit [--refs 1440,2880,5760,11520] [--N 1,2,4,8,15]
    python benchmarks/bench_reference.py cauchy --scene tail_orbit --family quality --ref 11520 \
        --freqs 720,1440,2880,5760,11520,23040 --N 4 [--params '{"solver.inextensibility": "none"}']

``grid``: for each reference of the families (frequency-consistent, quality) and each reference
frequency f, the reference runs once capturing its state before every frame; for each horizon N
(frames) its windows are run at 2f (the residual, as the bench does) and by the candidates of
every family at ``--cands`` Hz (the short-horizon errors). One JSON line per (reference, f, N).

``cauchy``: the one-window maps of several frequencies from the same snapshots (a reference at
``--ref`` Hz): the window ends of consecutive frequencies against each other. A model whose
short-horizon map converges at first order halves these differences at every doubling; a term
that is not consistent in the step makes them stall or grow (``--params`` switches parts off
to find it).

Restores are exact at the same frequency (tests/test_bench_short_horizon.py), so neither mode
measures the restore; the step counts are exact up to 23040 Hz (192 / 384 per 60 fps frame).
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from magica_py.bench import metrics as M
from magica_py.bench import short_horizon as S
from magica_py.bench.sweep import FAMILIES, reference_parameters
from magica_py.bench.variants import Variant, prepare, resolve_scene_path


def windows_of(full, run, n):
    starts = S.window_starts(run.frames, n)
    return S.ReferenceWindows(starts, n, [full.snapshots[s] for s in starts], run.positions, run.geometry)


def grid(a) -> None:
    t0 = time.time()
    groups = {}
    for fam in a.families.split(","):
        groups.setdefault(json.dumps(reference_parameters(FAMILIES[fam]), sort_keys=True), []).append(fam)
    for rp_text, users in groups.items():
        rp = json.loads(rp_text)
        for fr in [int(x) for x in a.refs.split(",")]:
            v = Variant(a.scene, resolve_scene_path(a.scene), parameters=rp, frequency=fr, duration=a.duration)
            run, full = S.run_reference(v, 1)
            for n in [int(x) for x in a.N.split(",")]:
                ref = windows_of(full, run, n)
                rec = {"scene": a.scene, "reference": "+".join(users), "f": fr, "N": n,
                       "residual_2f": 100 * S.candidate_window_errors(v.with_(frequency=2 * fr), ref).mean_rms}
                for fam in users:
                    for c in [int(x) for x in a.cands.split(",")]:
                        cand = v.with_(frequency=c, parameters=dict(FAMILIES[fam]))
                        rec[f"{fam}@{c}"] = 100 * S.candidate_window_errors(cand, ref).mean_rms
                rec["seconds"] = round(time.time() - t0)
                print(json.dumps(rec), flush=True)


def cauchy(a) -> None:
    params = reference_parameters(FAMILIES[a.family])
    params.update(json.loads(a.params))
    v = Variant(a.scene, resolve_scene_path(a.scene), parameters=params, frequency=a.ref, duration=a.duration)
    run, full = S.run_reference(v, 1)
    ref = windows_of(full, run, a.N)
    freqs = [int(x) for x in a.freqs.split(",")]
    ends = {}
    for f in freqs:
        p = prepare(v.with_(frequency=f))
        nodes = np.asarray(p.system.model.transform_index, dtype=np.int64)
        e = np.zeros((len(ref.snapshots),) + run.positions.shape[1:])
        for k, snapshot in enumerate(ref.snapshots):
            p.player.restore(snapshot, keep_model=True)
            for _ in range(a.N):
                p.player.step()
            e[k] = p.scene.hierarchy.world_position[nodes]
        ends[f] = e
    g = run.geometry

    def d(x, y):
        rms, _ = M.frame_errors(x, y, g.length_scale, g.moving)
        return 100 * float(np.mean(rms))

    print(f"{a.scene} {a.family} {a.params} from {a.ref} Hz snapshots, windows of {a.N} frames "
          f"(% of the chain, mean over {len(ref.snapshots)} windows)")
    print("against the snapshots' run:", " ".join(f"{f}: {d(ends[f], ref.end_positions()):.4g}" for f in freqs))
    print("consecutive frequencies:   ", " ".join(f"{f1}-{f2}: {d(ends[f1], ends[f2]):.4g}"
                                                  for f1, f2 in zip(freqs, freqs[1:])))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="mode", required=True)
    g = sub.add_parser("grid")
    g.add_argument("--scene", default="tail_orbit")
    g.add_argument("--families", default="frequency_consistent,quality,faithful")
    g.add_argument("--refs", default="1440,2880,5760,11520")
    g.add_argument("--N", default="1,2,4,8,15")
    g.add_argument("--cands", default="30,90,360,720")
    g.add_argument("--duration", type=float, default=None)
    c = sub.add_parser("cauchy")
    c.add_argument("--scene", default="tail_orbit")
    c.add_argument("--family", default="frequency_consistent")
    c.add_argument("--ref", type=int, default=1440)
    c.add_argument("--freqs", default="720,1440,2880,5760,11520,23040")
    c.add_argument("--N", type=int, default=1)
    c.add_argument("--duration", type=float, default=1.0)
    c.add_argument("--params", default="{}", help="JSON of parameter overrides (e.g. parts switched off)")
    a = p.parse_args(argv)
    (grid if a.mode == "grid" else cauchy)(a)
    return 0


if __name__ == "__main__":
    sys.exit(main())
