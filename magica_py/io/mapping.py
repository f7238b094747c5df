"""VRM spring-bone parameters → MagicaCloth2 BoneCloth parameters (dotted keys of ``params``).

The two solvers are different models, so the rule matches the *linearised* motion of one
chain segment (length L, small angle x = deviation arc from the rest direction) in both:

VRM (UniVRM / three-vrm, Verlet once per rendered frame, assumed 60 Hz), with
``k = stiffness·dt_vrm / L`` and ``D = dragForce``::

    x' = x + (1 - D)(x - x_prev) - k x            (+ gravityPower·dt_vrm / L, tangential)

MagicaCloth2 (per 90 Hz step, docs/solver.md §D.1 and §D.6), with ``δ = 0.2·damping`` (the damping table
is pre-multiplied by 0.2), ``a = angle_restoration.velocity_attenuation`` and ``F`` the
fraction of the angle the restoration removes per step — three iterations, each turning the
child by ``0.2·value`` of the remaining angle around a pivot at 0.1, 0.3, 0.5 of the edge,
so ``F = 1 - Π_k (1 - 0.2·value·(1 - p_k))``::

    u' = u(1-δ) + g·dt²            x' = (1 - F)(x + u')            u_end = u' - (1-a)·F·(x + u')
    (u = velocity·dt; ``velocity_attenuation`` is the share of a correction that is *not*
    turned into velocity)

Rule:

* ``damping``, ``angle_restoration.stiffness`` and ``velocity_attenuation`` are chosen so
  that a segment moves alike in both recurrences over 1.5 s: released at rest from a
  deflection, and pushed from rest by a constant force (normalised by its rest offset) —
  the RMS difference of the two trajectories sampled at 30 Hz is minimised by a grid
  search over the three values, then refined. When the VRM spring is stiffer or more damped
  than MagicaCloth2 can be, the closest reachable values are used and a note gives the
  remaining RMS mismatch. Without stiffness only the velocity decay is matched, in closed
  form: ``(1 - 0.2·damping)^90 = (1 - drag)^60``.
* ``gravity`` is chosen so that the static sag angle is VRM's. A VRM segment whose rest
  direction is horizontal rests exactly at ``θ = atan(gravityPower / stiffness)`` (its
  gravity and stiffness are both displacements per frame), while the fixed point of the
  MagicaCloth2 recurrence is ``x = g·cos θ·dt²·(1 - F) / (F·(1 - a(1 - δ)))``; so
  ``g = L·θ·F·(1 - a(1 - δ)) / ((1 - F)·cos θ·dt²)``, at most 20 m/s². Without stiffness
  ``g = gravityPower / dt_vrm``.
* ``gravity_direction`` = ``gravityDir`` (converted to Unity axes by the caller);
  ``radius`` = ``hitRadius`` (flat over depth).
* ``root_rotation`` = ``rotational_interpolation`` = 1: a VRM joint turns fully towards its
  tail (§E.2 with t = 1 makes every bone point at its children).
* ``angle_limit.use`` = false, ``tether``/``distance`` defaults (VRM keeps bone lengths
  exactly; MagicaCloth's distance constraint at stiffness 1 does the same),
  ``inertia.world_inertia`` = ``local_inertia`` = 1 (VRM feels all of the character's motion).
* ``center`` (VRM's simulation space node) → ``inertia.anchor`` with ``anchor_inertia`` 0:
  motion of the center is not felt — the closest MagicaCloth2 counterpart.

No counterpart: VRM's per-joint parameter variation along a chain is averaged (a note says
so); VRM 1.0 ``inside`` colliders (MagicaCloth2 only pushes particles *out*) are skipped;
VRM has no friction (``collider_collision.friction`` stays at MagicaCloth's 0.05); VRM is
frame-rate dependent, MagicaCloth2 is not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from magica_py.kernels import portable

VRM_FRAME_RATE = 60.0     # VRM springs step once per rendered frame; 60 Hz assumed
MC_STEP_RATE = 90.0       # MagicaCloth2 default simulation frequency (§A.3)
RESTORE_PIVOTS = (0.1, 0.3, 0.5)   # restoration pivot of the three iterations (§D.6)
GRAVITY_MAX = 20.0


@dataclass
class MappedParameters:
    """Dotted-key overrides for ``params.resolve_parameters`` plus what was approximated."""

    parameters: dict
    notes: list[str] = field(default_factory=list)
    mismatch: float = 0.0        # RMS trajectory mismatch of the linearised segment (module docstring)


def restoration_fraction(value):
    """F: fraction of the angle removed per step by the three restoration iterations."""
    value = np.asarray(value, dtype=np.float64)
    keep = np.ones_like(value)
    for p in RESTORE_PIVOTS:
        keep = keep * (1.0 - 0.2 * value * (1.0 - p))
    return 1.0 - keep


MATCH_TIME = 1.5      # s of motion compared by the dynamics fit
MATCH_RATE = 30.0     # Hz at which the two trajectories are compared


def _responses_vrm(k, drag, dt_vrm):
    """Release from x = 1 at rest and normalised response to a constant force, per frame."""
    frames = int(round(MATCH_TIME / dt_vrm))
    x = prev = 1.0
    y = y_prev = 0.0
    rel, step = np.empty(frames), np.empty(frames)
    for n in range(frames):
        x, prev = x + (1 - drag) * (x - prev) - k * x, x
        y, y_prev = y + (1 - drag) * (y - y_prev) - k * y + 1.0, y
        rel[n], step[n] = x, y
    return np.arange(1, frames + 1) * dt_vrm, rel, step * k   # a VRM segment rests at y = 1/k


def _responses_magica(value, damping, attenuation, dt_mc):
    """The same two responses of the MagicaCloth recurrence (broadcast over the arguments)."""
    f = restoration_fraction(value)
    d = 0.2 * np.asarray(damping, dtype=np.float64)
    a = np.asarray(attenuation, dtype=np.float64)
    f, d, a = np.broadcast_arrays(f, d, a)
    steps = int(round(MATCH_TIME / dt_mc))
    x, u = np.ones_like(f), np.zeros_like(f)
    y, w = np.zeros_like(f), np.zeros_like(f)
    held = 1.0 - a * (1.0 - d)
    with np.errstate(divide="ignore", invalid="ignore"):
        rest = np.where(f > 0, (1.0 - f) / (f * held), np.inf)       # fixed point for a unit force
    rel, step = np.empty(f.shape + (steps,)), np.empty(f.shape + (steps,))
    for n in range(steps):
        u = u * (1 - d)
        z = x + u
        x = (1 - f) * z
        u = u - (1 - a) * f * z
        w = w * (1 - d) + 1.0
        z = y + w
        y = (1 - f) * z
        w = w - (1 - a) * f * z
        rel[..., n] = x
        with np.errstate(invalid="ignore"):
            step[..., n] = np.where(np.isfinite(rest), y / rest, 0.0)
    return np.arange(1, steps + 1) * dt_mc, rel, step


def _match_dynamics(k, drag, dt_vrm, dt_mc):
    """(value, damping, attenuation, mismatch): MagicaCloth values whose released and
    forced segment motion best follows VRM's over MATCH_TIME (RMS in units of the
    deflection / of the rest offset)."""
    t_v, rel_v, step_v = _responses_vrm(k, drag, dt_vrm)
    grid_t = np.arange(1, int(MATCH_TIME * MATCH_RATE) + 1) / MATCH_RATE
    ref_rel = np.interp(grid_t, t_v, rel_v)
    ref_step = np.interp(grid_t, t_v, step_v) if k > 0 else None

    def cost(v, d, a):
        t_m, rel_m, step_m = _responses_magica(v, d, a, dt_mc)
        idx = np.clip(np.searchsorted(t_m, grid_t - 1e-12), 0, len(t_m) - 1)
        err = np.mean(np.square(rel_m[..., idx] - ref_rel), axis=-1)
        if ref_step is not None:
            err = err + np.mean(np.square(step_m[..., idx] - ref_step), axis=-1)
        return np.sqrt(np.where(np.isfinite(err), err, np.inf))

    if k == 0.0:   # no restoring force: only the velocity decay is matched, in closed form
        damping = min((1.0 - portable.pow(1.0 - drag, dt_mc / dt_vrm)) / 0.2, 1.0)
        return 0.0, damping, 0.8, float(cost(0.0, damping, 0.8))
    lo, hi = np.zeros(3), np.ones(3)
    best = None
    for _ in range(6):   # coarse grid, then zoom around the best point
        axes = [np.linspace(lo[i], hi[i], 13) for i in range(3)]
        v, d, a = np.meshgrid(*axes, indexing="ij")
        c = cost(v, d, a)
        j = np.unravel_index(int(np.argmin(c)), c.shape)
        best = (float(v[j]), float(d[j]), float(a[j]), float(c[j]))
        span = (hi - lo) / 4.0
        centre = np.array(best[:3])
        lo, hi = np.clip(centre - span, 0.0, 1.0), np.clip(centre + span, 0.0, 1.0)
    return best


def map_spring_parameters(stiffness: float, gravity_power: float, gravity_dir, drag_force: float,
                          hit_radius: float, segment_length: float, center: str | None = None,
                          vrm_rate: float = VRM_FRAME_RATE, mc_rate: float = MC_STEP_RATE) -> MappedParameters:
    """Apply the module's rule to one chain's VRM parameters (Unity-axis ``gravity_dir``)."""
    notes = []
    dt_vrm, dt_mc = 1.0 / vrm_rate, 1.0 / mc_rate
    drag = min(max(float(drag_force), 0.0), 1.0)
    stiffness = max(float(stiffness), 0.0)
    length = max(float(segment_length), 1e-4)
    k = stiffness * dt_vrm / length
    value, damping, attenuation, mismatch = _match_dynamics(k, drag, dt_vrm, dt_mc)
    if mismatch > 0.05:
        notes.append(f"stiffness {stiffness:g} / dragForce {drag_force:g} over {length:.3g} m segments: "
                     f"closest MagicaCloth2 motion differs by {100 * mismatch:.0f}% RMS (linearised segment)")

    power = max(float(gravity_power), 0.0)
    f = float(restoration_fraction(value))
    if stiffness > 0.0 and f > 0.0:
        theta = portable.atan(power / stiffness)
        held = 1.0 - attenuation * (1.0 - 0.2 * damping)
        gravity = length * theta * f * held / ((1.0 - f) * portable.cos(theta) * dt_mc * dt_mc)
    else:
        gravity = power / dt_vrm
    if gravity > GRAVITY_MAX:
        notes.append(f"gravityPower {gravity_power:g} maps to {gravity:.3g} m/s^2 > {GRAVITY_MAX:g}: clamped")
    gravity = min(gravity, GRAVITY_MAX)

    direction = [float(x) for x in gravity_dir]
    if math.sqrt(sum(x * x for x in direction)) < 1e-6:
        direction = [0.0, -1.0, 0.0]
        notes.append("gravityDir is zero: (0, -1, 0) used")
    radius = float(hit_radius)
    if radius < 0.001:
        notes.append(f"hitRadius {hit_radius:g} below MagicaCloth's minimum 0.001 m: raised")
        radius = 0.001
    if radius > 1.0:
        notes.append(f"hitRadius {hit_radius:g} above MagicaCloth's maximum 1 m: clamped")
        radius = 1.0
    parameters = {
        "gravity": round(gravity, 9),
        "gravity_direction": direction,
        "damping": {"value": round(damping, 9), "use_curve": False},
        "radius": {"value": radius, "use_curve": False},
        "angle_restoration.use": value > 0.0,
        "angle_restoration.stiffness": {"value": round(value, 9), "use_curve": False},
        "angle_restoration.velocity_attenuation": round(attenuation, 9),
        "angle_limit.use": False,
        "root_rotation": 1.0,
        "rotational_interpolation": 1.0,
        "inertia.world_inertia": 1.0,
        "inertia.local_inertia": 1.0,
    }
    if center is not None:
        parameters["inertia.anchor"] = center
        parameters["inertia.anchor_inertia"] = 0.0
        notes.append(f"VRM center {center!r} approximated by inertia.anchor (anchor_inertia 0)")
    return MappedParameters(parameters, notes, mismatch)
