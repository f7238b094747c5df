"""Where jobs run: a ``dask.distributed`` cluster, or this process.

``Executor(workers=None, scheduler=None, client=None)``:

* default: a ``LocalCluster`` on this machine, one single-threaded worker process per core
  (``workers`` to choose how many). A worker keeps its imported modules, so the numba
  kernels it loaded (from the on-disk cache, or compiled once) stay warm for every later
  job it runs;
* ``scheduler="tcp://host:8786"``: an existing Dask cluster (``dask scheduler`` and
  ``dask worker`` started on other machines, each with magica_py installed), unchanged;
* ``workers=0``: run in this process, one job after the other (debugging, small batches);
* ``client``: an existing ``dask.distributed.Client`` (tests, notebooks).

``map(fn, items)`` yields ``(index, result)`` as tasks finish. A task whose worker dies is
re-run elsewhere by the Dask scheduler (its ``allowed_failures``, 3 by default); a task that
kills every worker it lands on comes back as ``WorkerLost`` with the message, it does not stop
the others. ``fn`` must be importable on the workers (a module-level function).
"""
from __future__ import annotations

import logging
import os


class WorkerLost:
    """The result of a task whose workers kept dying (Dask's ``KilledWorker``)."""

    def __init__(self, message: str):
        self.message = message


class Executor:
    def __init__(self, workers: int | None = None, scheduler: str | None = None, client=None):
        if workers is not None and workers < 0:
            raise ValueError(f"workers: expected >= 0, got {workers}")
        if scheduler is not None and workers is not None:
            raise ValueError("give either a number of local workers or a scheduler address, not both")
        self.workers = workers
        self.scheduler = scheduler
        self.client = client
        self._own_client = None
        self._cluster = None

    @property
    def in_process(self) -> bool:
        return self.client is None and self.scheduler is None and self.workers == 0

    def describe(self) -> str:
        if self.in_process:
            return "this process"
        client = self.client
        info = client.scheduler_info() if client is not None else {}
        count = len(info.get("workers", {}))
        where = self.scheduler or ("LocalCluster" if self._cluster is not None else "Dask client")
        return f"{where} with {count} workers"

    def __enter__(self) -> "Executor":
        if self.in_process or self.client is not None:
            return self
        from dask.distributed import Client, LocalCluster

        if self.scheduler is not None:
            self._own_client = Client(self.scheduler)
        else:
            count = self.workers if self.workers is not None else (os.cpu_count() or 1)
            self._cluster = LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                         dashboard_address=None)
            self._own_client = Client(self._cluster)
        self.client = self._own_client
        return self

    def __exit__(self, *exc) -> None:
        if self._own_client is not None:
            self._own_client.close()
            self._own_client = None
            self.client = None
        if self._cluster is not None:
            # a worker busy with the last numba call can take longer than the nanny's grace
            # time to stop; it is then killed, which is what closing means here: not a warning
            nanny = logging.getLogger("distributed.nanny")
            level = nanny.level
            nanny.setLevel(logging.ERROR)
            try:
                self._cluster.close()
            finally:
                nanny.setLevel(level)
            self._cluster = None

    def map(self, fn, items: list, key_prefix: str = "magica-job", keys: list[str] | None = None):
        """Run ``fn(item)`` for every item; yields ``(index, result)`` in completion order
        (``WorkerLost`` as the result of a task whose workers kept dying)."""
        if self.in_process:
            for i, item in enumerate(items):
                yield i, fn(item)
            return
        from dask.distributed import as_completed
        from distributed.scheduler import KilledWorker

        import uuid

        token = uuid.uuid4().hex[:8]    # keys unique per call: a client may run several batches
        names = [f"{k}-{token}" for k in (keys or [f"{key_prefix}-{i}" for i in range(len(items))])]
        futures = [self.client.submit(fn, item, key=name, pure=False) for item, name in zip(items, names)]
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for future in as_completed(futures):
                try:
                    result = future.result()
                except KilledWorker as exc:
                    result = WorkerLost(f"the workers running this job died repeatedly ({exc})")
                yield index[future.key], result
                future.release()
        finally:
            for future in futures:          # interrupted: do not leave work on the cluster
                if not future.done():
                    future.cancel()
