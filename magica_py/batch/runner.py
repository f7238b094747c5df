"""Run a batch into an output folder, resumably.

Output folder layout::

    OUT/jobs/<job_id>.json     one finished job: its row (written as the job completes)
    OUT/rrd/<job_id>.rrd       its recording (outputs.rrd)
    OUT/bake/<job_id>.<ext>    its bake (outputs.bake)
    OUT/summary.parquet, OUT/summary.csv, OUT/pareto.png   the summary of every job of the file

A job whose ``jobs/<job_id>.json`` exists is not run again when the batch is restarted
(after an interruption, a crash of this process, or with more jobs added to the file);
failed jobs are run again only with ``retry_failed``. Results are written by this process
(artifacts come back from the workers as bytes), each under a temporary name and renamed,
so an interrupted write leaves no half file that a restart would trust.
"""
from __future__ import annotations

import json
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

from magica_py import atomic
from magica_py.batch.executor import Executor, WorkerLost
from magica_py.batch.jobs import Job
from magica_py.batch.run_job import run_job
from magica_py.runner import FrameProgress


@dataclass
class BatchReport:
    rows: list[dict]                      # one per job of the batch (finished ones)
    ran: list[str] = field(default_factory=list)       # job ids run by this call
    reused: list[str] = field(default_factory=list)    # job ids found in the output folder
    wall_time: float = 0.0                # s, running the jobs (cluster start-up excluded)
    startup_time: float = 0.0             # s, starting the cluster / connecting
    executor: str = ""

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r.get("status") != "ok"]


class JobProgress(FrameProgress):
    """The run loop's progress bar (tqdm: rate, ETA; terminals, logs, notebooks) counting jobs,
    with the failed ones: ``12/200 [00:10<02:30, 1.2 job/s, failed=1]``. ``done`` jobs were
    finished before this call (a resumed batch)."""

    def __init__(self, total: int, done: int = 0, stream=None):
        super().__init__(total, stream=stream, delay=0.0, unit="job", initial=done, desc="batch")
        self.failed = 0

    def update(self, ok: bool) -> None:  # noqa: D102 - one more job finished
        self.failed += 0 if ok else 1
        if not ok:
            self.bar.set_postfix(failed=self.failed, refresh=False)
        super().update(self.done + 1)


class _NoProgress:
    def update(self, ok: bool) -> None:
        pass

    def close(self) -> None:
        pass


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic.write_bytes(path, data)


def finished_rows(out: Path) -> dict[str, dict]:
    """Rows already in ``OUT/jobs`` (unreadable files are ignored: the job runs again)."""
    rows = {}
    for file in sorted((out / "jobs").glob("*.json")):
        try:
            row = json.loads(file.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(row, dict) and row.get("job_id") == file.stem:
            rows[file.stem] = row
    return rows


def store_result(out: Path, row: dict, artifacts: dict) -> None:
    """Artifacts first, then the row: a row on disk means the job's files are complete."""
    for name, data in artifacts.items():
        folder = "rrd" if name.endswith(".rrd") else "bake"
        _write_atomic(out / folder / name, data)
    _write_atomic(out / "jobs" / f"{row['job_id']}.json", json.dumps(row, indent=1, sort_keys=True).encode())


def run_batch(jobs: list[Job], out, executor: Executor | None = None, retry_failed: bool = False,
              progress: JobProgress | bool | None = None, on_result=None) -> BatchReport:
    """Run the ``jobs`` not yet finished in ``out`` on ``executor`` (default: a LocalCluster)
    and return every job's row. ``on_result(row)`` is called as each job finishes (after its
    files are written)."""
    out = Path(out)
    (out / "jobs").mkdir(parents=True, exist_ok=True)
    wanted = {j.job_id for j in jobs}
    previous = {k: v for k, v in finished_rows(out).items() if k in wanted}
    if retry_failed:
        previous = {k: v for k, v in previous.items() if v.get("status") == "ok"}
    todo = [j for j in jobs if j.job_id not in previous]
    report = BatchReport(rows=list(previous.values()), reused=list(previous))
    if progress is False:
        progress = _NoProgress()
    elif progress is None or progress is True:   # drawn on stderr (a terminal: in place; a log: lines)
        progress = JobProgress(len(jobs), len(previous))
    if not todo:
        return report
    executor = executor if executor is not None else Executor()
    t0 = _time.perf_counter()
    with executor:
        report.startup_time = _time.perf_counter() - t0
        report.executor = executor.describe()
        start = _time.perf_counter()
        try:
            for i, result in executor.map(run_job, [j.to_dict() for j in todo], keys=[j.job_id for j in todo]):
                job = todo[i]
                if isinstance(result, WorkerLost):
                    row, artifacts = {"job_id": job.job_id, **job.labels, "overrides": " ".join(job.overrides),
                                      "status": "failed", "error": result.message}, {}
                else:
                    row, artifacts = result
                store_result(out, row, artifacts)
                report.rows.append(row)
                report.ran.append(job.job_id)
                progress.update(row.get("status") == "ok")
                if on_result is not None:
                    on_result(row)
        finally:
            report.wall_time = _time.perf_counter() - start
            progress.close()
    return report
