"""magica-py batch: job files expand to their cross product with clear errors; a failing job is
recorded and the batch goes on; an interrupted batch resumes without recomputing; on a
LocalCluster of two workers a worker killed mid-job loses no row, and every job gives the
same bits (state hash) as in this process."""
from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from magica_py.batch import Executor, JobFileError, load_job_file, run_batch
from magica_py.batch.runner import finished_rows
from magica_py.batch.table import write_summary

FRAMES = 12


def job_file(tmp_path, repo_root, body: str, name="jobs.yaml"):
    path = tmp_path / name
    path.write_text(f"version: 1\nscenes: [{repo_root / 'configs' / 'tail_orbit.yaml'}]\nframes: {FRAMES}\n{body}")
    return path


def test_job_file_expands_the_cross_product_with_stable_ids(tmp_path, repo_root):
    path = job_file(tmp_path, repo_root, """
overrides:
  as_is: []
  heavy: [cloths.tail.parameters.gravity=9]
set:
  cloths.tail.parameters.damping: [0.05, 0.2, 0.4]
fps: [30, 60]
seeds: [0, 1]
""")
    jobs = load_job_file(path).jobs
    assert len(jobs) == 2 * 3 * 2 * 2
    assert len({j.job_id for j in jobs}) == len(jobs)
    assert [j.job_id for j in load_job_file(path).jobs] == [j.job_id for j in jobs]   # stable across loads
    heavy = [j for j in jobs if j.labels["override"] == "heavy" and j.labels["fps"] == 60 and j.labels["seed"] == 1
             and j.labels["set.cloths.tail.parameters.damping"] == "0.2"]
    assert len(heavy) == 1
    assert heavy[0].overrides == ("cloths.tail.parameters.gravity=9", "cloths.tail.parameters.damping=0.2",
                                  "scene.fps=60", "scene.seed=1")


@pytest.mark.parametrize("body, where, message", [
    ("fps: [0]", "fps[0]", "positive number"),
    ("seeds: [1.5]", "seeds[0]", "whole number"),
    ("outputs: {bake: fbx}", "outputs.bake", "glb, gltf, vrm, bvh"),
    ("overrides: {a: [damping]}", "overrides.a", "KEY=VALUE"),
    ("clips: {files: [missing.bvh]}", "clips.files[0]", "does not exist"),
    ("plot: {metric: beauty}", "plot.metric", "max_stretch"),
    ("colour: red", "colour", "unknown key"),
])
def test_job_file_errors_name_the_file_and_the_path(tmp_path, repo_root, body, where, message):
    path = job_file(tmp_path, repo_root, body)
    with pytest.raises(JobFileError) as info:
        load_job_file(path)
    assert info.value.where == where and message in info.value.message and str(path) in str(info.value)


def test_a_failing_job_is_recorded_and_an_interrupted_batch_resumes(tmp_path, repo_root):
    path = job_file(tmp_path, repo_root, """
set:
  cloths.tail.parameters.damping: [0.1, 0.3, 7.0]      # 7 is out of range: that job fails
fps: [30, 60]
""")
    jobs = load_job_file(path).jobs
    out = tmp_path / "out"
    seen = []

    def stop_after_two(row):
        seen.append(row["job_id"])
        if len(seen) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_batch(jobs, out, Executor(workers=0), on_result=stop_after_two)
    assert set(finished_rows(out)) == set(seen)
    report = run_batch(jobs, out, Executor(workers=0))
    assert sorted(report.reused) == sorted(seen) and len(report.ran) == len(jobs) - 2
    assert not set(report.ran) & set(seen)                                  # nothing recomputed
    rows = {r["job_id"]: r for r in report.rows}
    assert len(rows) == len(jobs)
    failed = [r for r in rows.values() if r["status"] == "failed"]
    assert len(failed) == 2 and all("damping" in r["error"] and "7" in r["error"] for r in failed)
    ok = [r for r in rows.values() if r["status"] == "ok"]
    assert all(r["frames"] == FRAMES and r["max_stretch"] >= r["mean_stretch"] >= 0.0 and r["ms_per_frame"] > 0
               for r in ok)
    parquet, csv = write_summary(report.rows, out)
    import pyarrow.parquet as pq

    table = pq.read_table(parquet)
    assert table.num_rows == len(jobs) and "state_hash" in table.column_names
    import pyarrow.csv as pacsv

    assert pacsv.read_csv(csv).num_rows == len(jobs)               # error messages span lines, quoted
    # a third run finds everything; --retry-failed runs only the failed jobs again
    assert run_batch(jobs, out, Executor(workers=0)).ran == []
    again = run_batch(jobs, out, Executor(workers=0), retry_failed=True)
    assert sorted(again.ran) == sorted(r["job_id"] for r in failed)


def _executing(dask_worker):
    return [str(ts.key) for ts in dask_worker.state.executing]


def test_two_worker_cluster_survives_a_killed_worker_with_the_same_bits(tmp_path, repo_root, monkeypatch):
    from dask.distributed import Client, LocalCluster

    # the killed worker's job folder cannot be removed by it: the workers' temporary folders
    # (they inherit the environment) go to the test's own folder
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    path = job_file(tmp_path, repo_root, "set:\n  cloths.tail.parameters.damping: [0.05, 0.1, 0.2, 0.4]\n")
    jobs = load_job_file(path).jobs
    reference = run_batch(jobs[:1], tmp_path / "here", Executor(workers=0)).rows[0]
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        result = {}
        thread = threading.Thread(target=lambda: result.update(
            report=run_batch(jobs, tmp_path / "cluster", Executor(client=client))))
        thread.start()
        killed = None
        deadline = time.monotonic() + 300
        while killed is None and thread.is_alive() and time.monotonic() < deadline:
            busy = {addr: keys for addr, keys in client.run(_executing).items() if keys}
            if busy:
                addr, keys = next(iter(busy.items()))
                pid = client.run(os.getpid, workers=[addr])[addr]
                os.kill(pid, signal.SIGKILL)
                killed = (pid, keys[0])
            time.sleep(0.05)
        thread.join(600)
        assert killed is not None, "no job was seen running"
        # the same cluster as an "existing cluster": magica-py batch --scheduler ADDRESS
        from magica_py.cli import main

        more = job_file(tmp_path, repo_root, "fps: [30, 45]\n", name="more.yaml")
        assert main(["batch", str(more), "--out", str(tmp_path / "remote"), "--scheduler",
                     cluster.scheduler_address, "--quiet"]) == 0
        assert len(finished_rows(tmp_path / "remote")) == 2
    report = result["report"]
    rows = {r["job_id"]: r for r in report.rows}
    assert set(rows) == {j.job_id for j in jobs}
    assert all(r["status"] == "ok" for r in rows.values()), [r.get("error") for r in rows.values()]
    victim = next(r for jid, r in rows.items() if killed[1].startswith(jid))
    assert not victim["worker"].endswith(f":{killed[0]}")                  # it ran again on another worker
    assert rows[reference["job_id"]]["state_hash"] == reference["state_hash"]   # same bits as this process


def test_a_worker_refuses_a_scene_file_that_changed_since_the_batch_started(tmp_path, repo_root):
    scene = tmp_path / "tail.yaml"
    scene.write_text((repo_root / "configs" / "tail_orbit.yaml").read_text())
    path = tmp_path / "jobs.yaml"
    path.write_text(f"version: 1\nscenes: [{scene}]\nframes: 3\n")
    jobs = load_job_file(path).jobs
    scene.write_text(scene.read_text() + "\n# edited\n")
    row = run_batch(jobs, tmp_path / "out", Executor(workers=0)).rows[0]
    assert row["status"] == "failed" and "differs from the one the batch was started with" in row["error"]


def test_batch_command_writes_the_summary_and_reports_bad_job_files(tmp_path, repo_root, capsys):
    from magica_py.cli import main

    path = job_file(tmp_path, repo_root, "fps: [30, 60]\noutputs: {rrd: true, bake: bvh}\n")
    out = tmp_path / "out"
    assert main(["batch", str(path), "--out", str(out), "--workers", "0", "--quiet"]) == 0
    for name in ("summary.parquet", "summary.csv", "pareto.png"):
        assert (out / name).stat().st_size > 0
    assert len(list((out / "rrd").glob("*.rrd"))) == 2 and len(list((out / "bake").glob("*.bvh"))) == 2
    assert (out / "pareto.png").read_bytes()[:4] == b"\x89PNG"
    bad = job_file(tmp_path, repo_root, "fps: [0]\n", name="bad.yaml")
    assert main(["batch", str(bad), "--out", str(tmp_path / "bad"), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert "bad.yaml: fps[0]: expected a positive number" in err and "Traceback" not in err
    assert not (tmp_path / "bad").exists()


def test_clips_axis_swaps_the_animation_clip(tmp_path, repo_root, shared_data):
    fox = shared_data / "gltf" / "Fox.glb"
    path = tmp_path / "clips.yaml"
    path.write_text(f"""version: 1
scenes: [{repo_root / 'configs' / 'fox_run.yaml'}]
frames: 4
clips:
  path: animation[0].clip
  files: ["{fox}#Run", "{fox}#Walk"]
""")
    jobs = load_job_file(path).jobs
    assert [j.labels["clip"] for j in jobs] == [f"{fox}#Run", f"{fox}#Walk"]
    assert jobs[1].overrides == (f"animation[0].clip={fox}#Walk",)
    rows = run_batch(jobs, tmp_path / "out", Executor(workers=0)).rows
    assert [r["status"] for r in rows] == ["ok", "ok"], [r.get("error") for r in rows]
    assert rows[0]["state_hash"] != rows[1]["state_hash"]            # another clip, another motion


def test_a_job_is_the_plain_run_of_its_scene_bit_for_bit(tmp_path, repo_root):
    """Instrumentation and warm-up change nothing: a job's final state hash is the one of the
    scene stepped by a bare player with the cloth system attached (what magica-py run does)."""
    from magica_py.batch.run_job import run_job, state_hash
    from magica_py.config import load_scene
    from magica_py.runtime.player import Player
    from magica_py.solver import attach

    path = job_file(tmp_path, repo_root, "fps: [45]\n")
    job = load_job_file(path).jobs[0]
    row, _ = run_job(job.to_dict())
    scene = load_scene(job.scene, list(job.overrides))
    player = Player.for_scene(scene)
    system = attach(player, scene)
    for _ in range(FRAMES):
        player.step()
    assert row["status"] == "ok" and row["state_hash"] == state_hash(scene, system)


def test_a_workers_first_job_of_a_scene_warms_up_with_fewer_collections(tmp_path, repo_root, monkeypatch):
    """The warm-up, where a cold cache compiles, runs inside ``jit.fewer_collections`` (as a
    ``magica-py run`` compile does); the job's own frames do not."""
    from contextlib import contextmanager

    from magica_py import jit
    from magica_py.batch import run_job as run_job_module

    real = jit.fewer_collections
    entered = []

    @contextmanager
    def recording():
        entered.append(run_job_module._WARMED.copy())
        with real():
            yield

    monkeypatch.setattr(jit, "fewer_collections", recording)
    monkeypatch.setattr(run_job_module, "_WARMED", set())
    job = load_job_file(job_file(tmp_path, repo_root, "fps: [45]\n")).jobs[0]
    row, _ = run_job_module.run_job(job.to_dict())
    assert row["status"] == "ok", row["error"]
    assert entered == [set()]                              # once, before the scene was warm
    row, _ = run_job_module.run_job(job.to_dict())         # the scene is warm: no warm-up
    assert row["status"] == "ok" and len(entered) == 1
