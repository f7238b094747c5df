"""``magica-py retarget-check SCENE.yaml [--set K=V ...]``: what every retargeted clip of a
scene does — the bone map on both sides (and where the skeleton's structure overruled a
name), the unmapped bones, the facing detected for source and target and the turn applied,
the hips heights and root-motion scale, each limb's rest alignment error after
retargeting, and the source bones whose motion has no target. Warnings (alignment worse
than 20°, undetermined facing, lost bones) are the ones ``validate`` and ``run`` print.

Exit codes as ``magica-py``: 0, 2 for a scene with problems (printed without traceback).
"""
from __future__ import annotations

import argparse
import sys
import warnings


def main_retarget_check(argv) -> int:
    parser = argparse.ArgumentParser(
        prog="magica-py retarget-check",
        description="For each retargeted clip of a scene: bone map, unmapped bones, detected facing, hips height, "
                    "rest alignment error per limb, source bones without a target.")
    parser.add_argument("scene", metavar="SCENE.yaml")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a value before validation (as for run / validate)")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    from magica_py.config.checker import Checker
    from magica_py.config.errors import ConfigError, format_path
    from magica_py.config.imports import RETARGET_REPORTS
    from magica_py.config.load import load_document
    from magica_py.config.schema import check_document

    reports: list = []
    token = RETARGET_REPORTS.set(reports)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)     # the report lists them
            doc = load_document(args.scene, args.overrides)
            checker = Checker(doc)
            check_document(checker, doc.data)
    except ConfigError as exc:
        print(exc.report(), file=sys.stderr)
        return 2
    finally:
        RETARGET_REPORTS.reset(token)
    if not reports:
        print(f"{args.scene}: no animation entry with 'retarget'")
    for path, rig, report in reports:
        print(f"{format_path(path)} -> rig {rig!r}")
        for line in report.lines():
            print("  " + line)
    if checker.issues:
        print(ConfigError(doc.source, checker.issues).report(), file=sys.stderr)
        return 2
    return 0
