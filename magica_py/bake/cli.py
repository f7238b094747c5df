"""``magica-py bake SCENE.yaml --out FILE.glb|FILE.gltf|FILE.vrm|FILE.bvh``."""
from __future__ import annotations

import argparse
import os
import sys
import warnings

DESCRIPTION = """\
Simulate a scene and write the motion of its bones as animation, one key per rendered frame:
glTF / GLB / VRM (for a rig loaded from such a file: an animation in a copy of that file, with
its mesh and skin) or BVH (for BVH rigs and generated rigs), in the format's own axes and units.
"""


def main_bake(argv) -> int:
    from magica_py.cli import EXIT_BAD_INPUT, EXIT_INTERRUPTED, EXIT_OK, _format_input_error, \
        _is_input_error, _show_warning

    p = argparse.ArgumentParser(prog="magica-py bake", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Examples:\n  magica-py bake configs/vrm_godette_mocap.yaml --out godette_baked.vrm\n"
                                       "  magica-py bake configs/fox_run.yaml --out fox_baked.glb --frames 120\n"
                                       "  magica-py bake configs/character_walk.yaml --out walk.bvh --bones 'skirt_*'")
    p.add_argument("scene", metavar="SCENE.yaml")
    p.add_argument("--out", required=True, metavar="FILE",
                   help="output file: .glb, .gltf (+ .bin beside it), .vrm (a VRM rig's copy) or .bvh")
    p.add_argument("--bones", action="append", default=[], metavar="GLOB",
                   help="bake only the rig bones matching this glob (repeatable; their parents come along "
                        "where the output needs them); default: every bone of the scene's rigs")
    p.add_argument("--frames", type=int, metavar="N", help="frames to simulate (default: the scene's)")
    p.add_argument("--rig", metavar="NAME", help="glTF output: the file rig whose copy is written "
                                                  "(needed when the bones come from several files)")
    p.add_argument("--units", metavar="UNIT", help="BVH output: m, cm, mm, inch, cmu or metres per file unit "
                                                   "(default: the BVH rig's own, metres for generated rigs)")
    p.add_argument("--name", metavar="NAME", help="glTF animation name (default: <scene>_baked)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a value of the scene before validation (as for magica-py run)")
    p.add_argument("--quiet", "-q", action="store_true")
    try:
        args = p.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    if args.frames is not None and args.frames < 1:
        print("magica-py bake: error: --frames: expected at least 1", file=sys.stderr)
        return EXIT_BAD_INPUT
    from magica_py.bake.bake import BakeError, bake_scene
    from magica_py.io.errors import AssetError

    from magica_py.runner import CompileWatch, FrameProgress, compile_text

    bar = None if args.quiet else FrameProgress(args.frames)

    def progress(done, total):
        if bar.bar.total != total:
            bar.bar.total = total
        bar.update(done)

    def note(text):
        if bar is not None:
            bar.write(f"magica-py bake: {text}")

    progress = None if bar is None else progress
    # a first run compiles the solver: said before it starts, left out of the bar's ETA and of
    # the times below, and reported apart
    compile_watch = CompileWatch(announce=note, on_end=None if bar is None else bar.pause_ended)
    try:
        with warnings.catch_warnings(), compile_watch:
            warnings.showwarning = _show_warning
            result = bake_scene(args.scene, args.out, args.overrides, args.bones or None, args.frames, args.rig,
                                args.units, args.name, progress, compile_watch)
    except KeyboardInterrupt:
        print("magica-py bake: interrupted (nothing written)", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (BakeError, AssetError) as exc:
        print(f"magica-py bake: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:  # noqa: BLE001 - bad input is reported without a traceback
        if not _is_input_error(exc):
            raise
        print(_format_input_error(exc), file=sys.stderr)
        return EXIT_BAD_INPUT
    finally:
        if bar is not None:
            bar.close()
    if not args.quiet:
        for note in result.notes:
            print(f"magica-py bake: {note}", file=sys.stderr)
        m = result.motion
        print(f"{os.path.relpath(result.out)}: {len(m.names)} bones x {m.frames} frames, {result.bytes / 1e6:.2f} MB; "
              f"loaded in {result.load_seconds:.2f} s, simulated in {result.simulate_seconds:.2f} s, "
              f"written in {result.write_seconds:.2f} s{compile_text(result.compile_seconds)}")
    return EXIT_OK
