"""The extra threads of a parallel frame (magica_py/threads.py): one job per thread per
frame, errors raised in the calling thread, threads that leave when told or when unused, new
threads in a forked child."""
from __future__ import annotations

import gc
import os
import threading
import time

import pytest

from magica_py.threads import FrameThreads


def test_each_job_runs_once_on_a_thread_of_its_own_per_frame():
    pool = FrameThreads(3)
    seen = []
    for frame in range(50):
        pool.run([lambda k=k, frame=frame: seen.append((frame, k, threading.get_ident())) for k in range(3)])
        pool.join()
    assert sorted((f, k) for f, k, _ in seen) == [(f, k) for f in range(50) for k in range(3)]
    idents = {k: {ident for _, kk, ident in seen if kk == k} for k in range(3)}
    assert all(len(v) == 1 for v in idents.values())            # job k always on thread k
    assert len({next(iter(v)) for v in idents.values()} | {threading.get_ident()}) == 4
    pool.close()


def test_fewer_jobs_than_threads_and_a_jobs_error_is_raised_by_join():
    pool = FrameThreads(2)
    done = []

    def fail():
        raise ValueError("stage blew up")

    pool.run([fail, lambda: done.append(1)])
    with pytest.raises(ValueError, match="stage blew up"):
        pool.join()
    assert done == [1]                       # the other thread's job finished before join raised
    pool.run([lambda: done.append(2)])       # the threads serve the next frame
    pool.join()
    assert done == [1, 2]
    with pytest.raises(ValueError, match="3 jobs for 2 threads"):
        pool.run([done.clear] * 3)
    pool.close()


def test_threads_leave_when_closed_or_when_the_pool_is_collected():
    pool = FrameThreads(2, name="closed-pool")
    pool.close()
    unused = FrameThreads(2, name="unused-pool")
    del unused
    gc.collect()
    for thread in threading.enumerate():
        if thread.name.startswith(("closed-pool", "unused-pool")):
            thread.join(timeout=5.0)
    assert not [t.name for t in threading.enumerate() if t.name.startswith(("closed-pool", "unused-pool"))]
    with pytest.raises(RuntimeError, match="closed"):
        pool.run([])


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX fork")
def test_a_forked_child_runs_its_jobs_on_threads_of_its_own():
    """After a fork the parent's threads do not exist in the child: a pool used there starts
    its own instead of handing jobs to no one (and waiting for ever in ``join``)."""
    pool = FrameThreads(2, name="forked-pool")
    pool.run([lambda: None, lambda: None])
    pool.join()
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:   # the child: run a frame's jobs, report, leave without the parent's exit work
        code = 1
        try:
            seen = []
            pool.run([lambda: seen.append(threading.get_ident()), lambda: seen.append(threading.get_ident())])
            pool.join()
            os.write(write, b"ok" if len(set(seen)) == 2 and threading.get_ident() not in seen else b"bad")
            code = 0
        finally:
            os._exit(code)
    os.close(write)
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        time.sleep(0.05)
    else:
        os.kill(pid, 9)
        os.waitpid(pid, 0)
        pytest.fail("the forked child's jobs never ran")
    assert os.read(read, 16) == b"ok" and os.WEXITSTATUS(status) == 0
    os.close(read)
    pool.run([lambda: None])   # the parent's threads serve on
    pool.join()
    pool.close()
