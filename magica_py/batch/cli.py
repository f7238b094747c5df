"""``magica-py batch JOBS.yaml [--out DIR] [--workers N | --scheduler ADDRESS]``."""
from __future__ import annotations

import argparse
import os
import sys

DESCRIPTION = """\
Run every job of a job file (the cross product of its scenes, clips, override sets, swept --set
values, frame rates and seeds; format: docs/batch.md) on a Dask cluster: by default a LocalCluster
on this machine with one worker per core, or an existing cluster with --scheduler. Each job's
metrics land in OUT/jobs/ as it finishes; jobs already there are not run again (restart an
interrupted batch with the same command). The summary is OUT/summary.parquet, OUT/summary.csv
and OUT/pareto.png.
"""


def main_batch(argv) -> int:
    from magica_py import first_run
    from magica_py.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_OK

    p = argparse.ArgumentParser(prog="magica-py batch", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("jobs", metavar="JOBS.yaml")
    p.add_argument("--out", metavar="DIR", help="output folder (default: batches/<job file name>/)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="local worker processes (default: one per core); 0 runs the jobs in this process")
    where.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    p.add_argument("--retry-failed", action="store_true", help="run the failed jobs of an earlier run again")
    p.add_argument("--list", action="store_true", help="print the jobs and whether they are done; run nothing")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no summary")
    try:
        args = p.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    from magica_py.batch.executor import Executor
    from magica_py.batch.jobs import JobFileError, load_job_file
    from magica_py.batch.runner import finished_rows, run_batch
    from magica_py.batch.table import pareto_plot, short_label, write_summary

    if args.workers is not None and args.workers < 0:
        print("magica-py batch: error: --workers: expected 0 or more", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        job_file = load_job_file(args.jobs)
    except JobFileError as exc:
        print(f"magica-py batch: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    out = __import__("pathlib").Path(args.out or os.path.join("batches", job_file.name))
    if out.exists() and not out.is_dir():
        print(f"magica-py batch: error: --out {str(out)!r} is a file, expected a folder", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.list:
        done = finished_rows(out) if out.is_dir() else {}
        try:
            for job in job_file.jobs:
                state = done.get(job.job_id, {}).get("status", "todo")
                print(f"{job.job_id}  {state:6}  {job.labels['scene']}: "
                      f"{short_label({**job.labels, 'job_id': job.job_id})}")
        except BrokenPipeError:   # `magica-py batch JOBS --list | head`
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    executor = Executor(workers=args.workers, scheduler=args.scheduler)
    if not args.quiet:
        print(f"magica-py batch: {len(job_file.jobs)} jobs from {args.jobs} -> {out}", file=sys.stderr)
        if args.scheduler is None and not first_run.frame_kernel_cached():
            # local workers share this machine's kernel cache: an empty one means their first
            # jobs compile the solver before the bar moves (the jobs' timings leave it out)
            print("magica-py batch: no compiled solver in the kernel cache yet: each worker compiles it before its "
                  "first job (first run only; compiled kernels are cached for the next runs; this can take a minute "
                  "or more, and the jobs' timings leave it out)", file=sys.stderr)
    interrupted = False
    try:
        report = run_batch(job_file.jobs, out, executor, retry_failed=args.retry_failed,
                           progress=None if not args.quiet else False)
    except KeyboardInterrupt:
        interrupted = True
        report = None
    except OSError as exc:
        print(f"magica-py batch: error: cannot reach the cluster or write {out}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    rows = list(finished_rows(out).values()) if out.is_dir() else []
    wanted = {j.job_id for j in job_file.jobs}
    rows = [r for r in rows if r["job_id"] in wanted]
    if rows:
        parquet, csv = write_summary(rows, out)
        plot = pareto_plot(rows, out / "pareto.png", job_file.metric, job_file.cost, job_file.name)
    if interrupted:
        print(f"magica-py batch: interrupted: {len(rows)} of {len(job_file.jobs)} jobs are in {out}; run the same "
              "command again to finish the others", file=sys.stderr)
        return EXIT_INTERRUPTED
    failed = [r for r in rows if r.get("status") != "ok"]
    if not args.quiet:
        if report.ran:
            print(f"ran {len(report.ran)} jobs on {report.executor} in {report.wall_time:.1f} s "
                  f"(+{report.startup_time:.1f} s start-up); {len(report.reused)} found done in {out}", file=sys.stderr)
        else:
            print(f"every job was already done in {out}", file=sys.stderr)
        for r in failed[:10]:
            first = (r.get("error") or "").strip().splitlines()[:1]
            print(f"  failed {r['job_id']} ({short_label(r)}): {first[0] if first else '?'}", file=sys.stderr)
        print(f"{len(rows) - len(failed)} ok, {len(failed)} failed -> {parquet}, {csv}, {plot}")
    return EXIT_OK if not failed else EXIT_FAILURE
