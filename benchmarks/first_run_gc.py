"""Python's garbage collector in a first run: ``magica-py run SCENE --no-rrd --frames 10`` in this
process, with every collection timed by generation (``gc.callbacks``).

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/first_run_gc.py tail_orbit [--gc default]

``--gc``: ``default`` (the collector as the run leaves it: ``jit.fewer_collections`` during
its compiles), ``off`` (``gc.disable()`` for the whole process), ``freeze`` (``gc.freeze()``
after the imports) or three thresholds ``A,B,C`` for the whole process (``gc.set_threshold``;
a run's compile then leaves them as they are). Prints the run's summary line, then the
collections (count and seconds per generation), the wall time and the peak memory of this
process (the compile helper, a forked process, is not counted). Set ``MAGICA_COMPILE_HELPER=0``
to compile everything in this process.
"""
from __future__ import annotations

import argparse
import gc
import os
import pathlib
import resource
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
# this measures the compile: the run must not take the interpreted first-run tier (magica_py/first_run.py)
os.environ.setdefault("MAGICA_FIRST_RUN", "compile")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", help="a config name under configs/ (tail_orbit, character_walk, crowd, ...)")
    ap.add_argument("--gc", default="default", help="default | off | freeze | A,B,C (thresholds)")
    args = ap.parse_args(argv)
    counts = [0, 0, 0]
    seconds = [0.0, 0.0, 0.0]
    started = {}

    def timed(phase, info):
        g = info["generation"]
        if phase == "start":
            started[g] = time.perf_counter()
        else:
            counts[g] += 1
            seconds[g] += time.perf_counter() - started[g]

    gc.callbacks.append(timed)
    if args.gc == "off":
        gc.disable()
    elif args.gc not in ("default", "freeze"):
        thresholds = tuple(int(x) for x in args.gc.split(","))
        gc.set_threshold(*thresholds)
        from magica_py import jit

        jit.COMPILE_GC_THRESHOLDS = thresholds   # the run's compiles keep them
    start = time.perf_counter()
    from magica_py.cli import main as cli_main

    if args.gc == "freeze":
        gc.freeze()
    rc = cli_main(["run", str(ROOT / "configs" / f"{args.scene}.yaml"), "--no-rrd", "--frames", "10"])
    wall = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"gc {args.gc}: collections by generation {counts}, "
          f"{' / '.join(f'{s:.2f}' for s in seconds)} s; wall {wall:.1f} s; peak {peak:.0f} MB")
    return rc or 0


if __name__ == "__main__":
    sys.exit(main())
