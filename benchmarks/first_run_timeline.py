"""A first run's compile timeline in both of its processes: the system's and the compile
helper's (``magica_py/solver/compile_helper.py``), from numba's documented event API
(``numba:compile``).

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/first_run_timeline.py tail_orbit [--frames N] [--depth N]

Runs ``magica-py run configs/NAME.yaml --no-rrd --frames N`` in this process (the command line's
own code, with its compile helper when ``compile_helper.wanted`` allows one) and prints, in
seconds since the start:

* the system process's outermost compiles of 0.3 s or more, and with ``--depth N`` the
  compiles nested up to N levels under them (0.2 s or more, indented): which of the frame
  kernel's callees this process compiled itself and when;
* the helper's share (fork to end) and its compiles one level under it (the stages);
* the functions both processes compiled after the fork (work done twice);
* the balance: the serial start before the fork, the window where both compile, the serial
  end after the helper is done (the frame kernel's own module is compiled there), and how long
  the helper idles while the system's process finishes.

The helper writes its rows to a temporary file before it leaves (this script wraps the
helper's share; the helper itself writes nothing). With an empty cache only: with a warm one
nothing compiles. ``first_run_gc.py`` times the garbage collector in the same run;
``compile_profile.py`` splits one process's compile by function and compiler pass.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
# this measures the compile: the run must not take the interpreted first-run tier (magica_py/first_run.py)
os.environ.setdefault("MAGICA_FIRST_RUN", "compile")
START = time.perf_counter()


class Recorder:
    """numba:compile events -> (start s, end s, depth, function) rows, times since ``START``."""

    def __init__(self):
        self.rows: list[tuple[float, float, int, str]] = []
        self._open: list[float] = []

    def listener(self):
        from numba.core import event

        recorder = self

        class Listener(event.Listener):
            def on_start(self, ev):
                recorder._open.append(time.perf_counter() - START)

            def on_end(self, ev):
                start = recorder._open.pop()
                fn = getattr(ev.data["dispatcher"], "py_func", None)
                name = f"{fn.__module__}.{fn.__qualname__}" if fn is not None else "?"
                recorder.rows.append((start, time.perf_counter() - START, len(recorder._open), name))

        return Listener()


def wrap_helper(recorder: Recorder, path: str, forks: list) -> None:
    """The helper leaves with ``os._exit`` (no exit handler runs): its share writes the rows
    recorded in the helper (the inherited listener's rows since the fork) to ``path`` when
    done. The forks (the early one at a system's construction, or the one at its first frame
    call) append their time to ``forks`` in the system's process."""
    from magica_py.solver import compile_helper

    share = compile_helper._compile_helper_share
    for name in ("fork_early", "start"):
        def timed(*args, _fork=getattr(compile_helper, name), **kwargs):
            forks.append(time.perf_counter() - START)
            return _fork(*args, **kwargs)

        setattr(compile_helper, name, timed)

    def recorded_share(*args, **kwargs):
        forked = time.perf_counter() - START
        ok = False
        try:
            share(*args, **kwargs)
            ok = True
        finally:
            with open(path, "w") as f:
                json.dump({"start": forked, "end": time.perf_counter() - START, "ok": ok,
                           "rows": [r for r in recorder.rows if r[0] >= (forks[-1] if forks else forked)]}, f)

    compile_helper._compile_helper_share = recorded_share


def report(main_rows, helper, forks, end, depth_shown: int = 0) -> None:
    print("system process, outermost compiles of 0.3 s or more" +
          (f" (and those nested up to {depth_shown} levels under them, 0.2 s or more):" if depth_shown else ":"))
    for s, e, depth, name in sorted(main_rows, key=lambda row: (row[0], row[2])):   # a caller before its callees
        if (depth == 0 and e - s >= 0.3) or (0 < depth <= depth_shown and e - s >= 0.2):
            print(f"  {s:6.1f} - {e:6.1f}  {e - s:5.1f} s  {'  ' * depth}{name}")
    if helper is None:
        print("no compile helper ran (compile_helper.wanted refused one, or the cache was warm)")
        return
    h0, h1 = (forks[0] if forks else helper["start"]), helper["end"]
    print(f"compile helper: forked at {h0:.1f} s, its share (the stages) from {helper['start']:.1f} s to "
          f"{h1:.1f} s ({'ok' if helper['ok'] else 'failed'}); its compiles one level under its share:")
    for s, e, depth, name in helper["rows"]:
        if depth == 1:
            print(f"  {s:6.1f} - {e:6.1f}  {e - s:5.1f} s  {name}")
    in_helper = {}
    for s, e, depth, name in helper["rows"]:
        in_helper.setdefault(name, (s, e))
    twice = [(name, (s, e), in_helper[name]) for s, e, depth, name in main_rows
             if s >= h0 and name in in_helper and e - s >= 0.05]
    print("compiled by both processes after the fork (0.05 s or more in the system's):")
    for name, (s, e), (hs, he) in sorted(twice, key=lambda t: t[1][0] - t[1][1]):
        print(f"  here {s:6.1f} - {e:6.1f} ({e - s:4.1f} s), in the helper {hs:6.1f} - {he:6.1f} ({he - hs:4.1f} s)  {name}")
    if not twice:
        print("  none")
    print(f"balance: serial start {h0:.1f} s, both compiling {h1 - h0:.1f} s, serial end "
          f"{max(end - h1, 0.0):.1f} s (the helper idle), whole run {end:.1f} s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", help="a config of configs/ (name without .yaml)")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--depth", type=int, default=0,
                    help="also list the system process's compiles nested up to this many levels")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from numba.core import event

    recorder = Recorder()
    event.register("numba:compile", recorder.listener())
    fd, path = tempfile.mkstemp(prefix="magica-helper-timeline-", suffix=".json")
    os.close(fd)
    os.unlink(path)   # the helper creates it when its share ends
    forks: list[float] = []
    wrap_helper(recorder, path, forks)
    from magica_py.cli import main as cli_main

    code = cli_main(["run", str(ROOT / "configs" / f"{args.scene}.yaml"), "--no-rrd", "--frames", str(args.frames)])
    end = time.perf_counter() - START
    helper = None
    if os.path.exists(path):
        with open(path) as f:
            helper = json.load(f)
        os.unlink(path)
    report(recorder.rows, helper, forks, end, args.depth)
    return code


if __name__ == "__main__":
    sys.exit(main())
