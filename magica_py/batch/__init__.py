"""Batch: thousands of independent simulations on a Dask cluster, one table of metrics (issue 21).

* ``jobs.py``: the job file (YAML) and its cross product of scenes x clips x override sets x
  swept ``--set`` values x frame rates x seeds; a job's id hashes everything that determines
  its result;
* ``run_job.py``: one job on a worker (the scene as ``magica-py run`` runs it, instrumented by
  ``bench.variants.run_variant``), never raising: a row of metrics, its state hash, and its
  artifacts (recording, bake) as bytes;
* ``executor.py``: a ``dask.distributed`` LocalCluster (default), an existing cluster
  (``--scheduler``) or this process; worker deaths are re-run by the scheduler;
* ``runner.py``: resumable runs into an output folder, the progress bar;
* ``table.py``: the summary (Parquet + CSV) and the Pareto plot;
* ``cli.py``: ``magica-py batch JOBS.yaml``.

``magica-py bench`` runs its frequency sweep through ``Executor`` too (``bench/cli.py``).
"""
from __future__ import annotations

from magica_py.batch.executor import Executor, WorkerLost
from magica_py.batch.jobs import Job, JobFile, JobFileError, load_job_file
from magica_py.batch.runner import BatchReport, run_batch

__all__ = ["Executor", "WorkerLost", "Job", "JobFile", "JobFileError", "load_job_file", "BatchReport", "run_batch"]
