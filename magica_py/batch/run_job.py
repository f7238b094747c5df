"""One batch job, on whatever process runs it (a Dask worker, or this process).

``run_job(job)`` loads the scene with the job's ``--set`` strings, runs it exactly as
``magica-py run`` does (same player, same cloth system, the scene's own frequency and step
cap), instrumented by ``bench.variants.run_variant`` (per-frame stretch, penetration,
speed, resets, wall time), and returns ``(row, artifacts)``:

* ``row``: the job's labels and metrics (``table.METRIC_COLUMNS``), ``status`` ("ok" or
  "failed"), ``error`` (the message; the traceback is in ``traceback``), ``state_hash``
  (SHA-256 of the final transforms and particle state: the same job gives the same bits on
  any worker), ``worker`` (host:pid);
* ``artifacts``: file name -> bytes (the ``.rrd`` recording and / or the bake), written by
  the client into the output folder, so workers need no shared file system.

It never raises: a failing job is a row with its error, and the batch goes on.
"""
from __future__ import annotations

import hashlib
import os
import socket
import tempfile
import time as _time
import traceback
from pathlib import Path


def _error_text(exc: BaseException) -> str:
    report = getattr(exc, "report", None)
    if callable(report):
        try:
            return str(report())
        except Exception:  # noqa: BLE001 - fall back to the plain message
            pass
    return f"{type(exc).__name__}: {exc}"


def state_hash(scene, system) -> str:
    """SHA-256 (hex, 16 digits) of the final local and world poses of every transform and of
    the solver's particle state (positions, velocities)."""
    import numpy as np

    h = scene.hierarchy
    digest = hashlib.sha256()
    arrays = [h.local_position, h.local_rotation, h.local_scale, h.world_position, h.world_rotation]
    particles = getattr(system, "particles", None)
    for name in ("position", "velocity", "next_pos", "old_pos"):
        value = getattr(particles, name, None)
        if isinstance(value, np.ndarray):
            arrays.append(value)
    for a in arrays:
        digest.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return digest.hexdigest()[:16]


# Parsed scene files of this process, by (path, SHA-256 checked above): a worker runs many
# jobs of one scene, and parsing its YAML again is a third of a small job's time. Each job
# gets its own deep copy to apply its overrides to.
_DOCUMENTS: dict = {}


def _load_scene(job):
    """``config.load_scene(job.scene, job.overrides)``, with the parsed file cached."""
    import copy

    from magica_py.config import load_scene
    from magica_py.config.document import read_document
    from magica_py.config.load import build_scene, validate_document
    from magica_py.config.overrides import apply_overrides

    if not job.scene_sha256:
        return load_scene(job.scene, list(job.overrides))
    key = (job.scene, job.scene_sha256)
    if key not in _DOCUMENTS:
        _DOCUMENTS[key] = read_document(job.scene)
    doc = copy.deepcopy(_DOCUMENTS[key])
    if job.overrides:
        apply_overrides(doc, list(job.overrides))
    # the scene text as run (YAML dumped again after overrides) is read only by the recording
    # and the bake (which rigs came from which file)
    text = doc.effective_text() if (job.rrd or job.bake) else None
    return build_scene(validate_document(doc), Path(job.scene), text, list(job.overrides))


def _prepare(job):
    """Scene, player and cloth system as ``magica-py run`` builds them (no frequency or step
    changes: the job is the scene as a user runs it)."""
    from magica_py.bench.variants import Prepared, attach_cloth
    from magica_py.runtime.player import Player

    if job.scene_sha256:
        try:
            seen = hashlib.sha256(Path(job.scene).read_bytes()).hexdigest()
        except OSError as exc:
            raise FileNotFoundError(f"{job.scene}: not readable on worker {socket.gethostname()} ({exc.strerror}); "
                                    "every worker needs the scene files at the same path (docs/batch.md)") from None
        if seen != job.scene_sha256:
            raise ValueError(f"{job.scene}: the file on worker {socket.gethostname()} differs from the one the "
                             "batch was started with; keep the workers' checkouts in step (docs/batch.md)")
    scene = _load_scene(job)
    player = Player.for_scene(scene)
    # a batch runs one job per core: a job keeps to one thread unless its scene asks for more
    single = False if scene.settings.threads == "auto" else None
    system = attach_cloth(player, scene, parallel=single)
    frames = job.frames if job.frames is not None else scene.settings.frame_count()
    if frames is None:
        raise ValueError("the scene runs on the wall clock for a duration: give the job file 'frames'")
    return Prepared(scene, player, system, int(frames), int(scene.settings.simulation_frequency))


def run_job(job_data: dict) -> tuple[dict, dict]:
    """Run one job (``jobs.Job.to_dict()``); see the module docstring."""
    from magica_py.batch.jobs import Job

    job = Job.from_dict(job_data)
    row = {"job_id": job.job_id, **job.labels, "overrides": " ".join(job.overrides), "frames": job.frames,
           "status": "failed", "error": None, "traceback": None,
           "worker": f"{socket.gethostname()}:{os.getpid()}", "started": _time.time()}
    artifacts: dict[str, bytes] = {}
    start = _time.perf_counter()
    try:
        with tempfile.TemporaryDirectory(prefix="magica-job-") as tmp:
            row.update(_run(job, Path(tmp), artifacts))
        row["status"] = "ok"
    except Exception as exc:  # noqa: BLE001 - a job never stops the batch (Ctrl-C still does)
        row["error"] = _error_text(exc)
        row["traceback"] = traceback.format_exc()
        artifacts.clear()
    row["job_s"] = _time.perf_counter() - start
    return row, artifacts


# Scenes this process has already run: the first job of a scene on a worker first steps it
# untimed for a few frames, so that loading the kernels from numba's cache (or compiling them)
# does not land in that job's ms_per_frame. The worker keeps them for every later job. Where
# they compile (a cold cache), Python's garbage collector runs less often meanwhile
# (``jit.fewer_collections``, as in ``magica-py run``).
_WARMED: set[str] = set()
WARMUP_FRAMES = 3


def _warm_up(job) -> float:
    from magica_py import jit

    if job.scene in _WARMED:
        return 0.0
    start = _time.perf_counter()
    with jit.fewer_collections():
        p = _prepare(job)
        for _ in range(min(WARMUP_FRAMES, p.frames)):
            p.player.step()
    _WARMED.add(job.scene)
    return _time.perf_counter() - start


def _run(job, tmp: Path, artifacts: dict) -> dict:
    import numpy as np

    from magica_py.bench.variants import Variant, run_variant

    warmup = _warm_up(job)
    t0 = _time.perf_counter()
    p = _prepare(job)
    setup = _time.perf_counter() - t0
    scene, player = p.scene, p.player
    recorder = capture = plan = None
    if job.rrd:
        from magica_py.sinks import attach as attach_sink
        from magica_py.sinks.recorder import SinkOptions

        recorder = attach_sink(player, scene, SinkOptions(rrd=str(tmp / f"{job.job_id}.rrd")))
    if job.bake:
        from magica_py.bake.bake import file_rigs, plan_bones
        from magica_py.bake.capture import PoseCapture

        rigs = file_rigs(scene)
        bones, source = plan_bones(scene, Path(f"bake.{job.bake}"), rigs=rigs)
        plan = (rigs, source)
        capture = PoseCapture(scene.hierarchy, bones, p.frames).attach(player)
    ok = False
    try:
        run = run_variant(Variant(job.job_id, job.scene, job.overrides), record_positions=False, prepared=p)
        ok = True
    finally:
        if recorder is not None:
            recorder.close(ok)
    frame_wall = float(run.frame_wall.sum())
    result = {
        "particles": int(run.particle_count),
        "frames": int(run.frames),
        "max_stretch": float(run.edge_stretch.max(initial=0.0)),
        "mean_stretch": float(run.edge_stretch_mean.mean()) if run.frames else 0.0,
        "max_root_stretch": float(run.root_stretch.max(initial=0.0)),
        "max_penetration": float(run.penetration.max(initial=0.0)),
        "mean_penetration": float(run.penetration.mean()) if run.frames else 0.0,
        "max_speed": float(run.display_speed.max(initial=0.0)),
        "mean_speed": float(run.display_speed.mean()) if run.frames else 0.0,
        "resets": int(run.guard_resets.sum()),
        "non_finite_frames": int(np.count_nonzero(run.non_finite)),
        "particle_steps": float(run.particle_steps.sum()),
        "warmup_s": warmup,
        "setup_s": setup,
        "run_s": frame_wall,
        "ms_per_frame": 1000.0 * frame_wall / max(run.frames, 1),
        "ms_per_sim_second": 1000.0 * frame_wall / float(run.times[-1]) if run.frames and run.times[-1] > 0 else None,
        "particle_steps_per_s": float(run.particle_steps.sum()) / frame_wall if frame_wall > 0 else 0.0,
        "state_hash": state_hash(scene, p.system),
        "rrd": None,
        "bake": None,
    }
    if recorder is not None:
        name = f"{job.job_id}.rrd"
        artifacts[name] = (tmp / name).read_bytes()
        result["rrd"] = f"rrd/{name}"
    if capture is not None:
        from magica_py.bake.bake import bake_capture

        name = f"{job.job_id}.{job.bake}"
        target = tmp / name
        bake_capture(scene, capture.result(), target, plan[1], plan[0])
        artifacts[name] = target.read_bytes()
        if job.bake == "gltf":
            artifacts[target.with_suffix(".bin").name] = target.with_suffix(".bin").read_bytes()
        result["bake"] = f"bake/{name}"
    return result
