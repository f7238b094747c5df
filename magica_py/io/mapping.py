"""VRM spring-bone parameters → MagicaCloth2 BoneCloth parameters (dotted keys of ``params``).

The two solvers are different models, so no mapping is exact. The rule below matches the
*linearised small-angle* behaviour of one chain segment of length L in both solvers at their
nominal rates — VRM springs are integrated once per rendered frame (UniVRM, three-vrm:
frame-rate dependent, assumed 60 Hz), MagicaCloth2 steps at 90 Hz (ref §A.5):

* ``damping`` from ``dragForce``: VRM keeps ``(1 - drag)`` of the Verlet velocity per frame,
  MagicaCloth keeps ``(1 - 0.2·damping)`` per step (ref §D.1, the table is pre-multiplied
  by 0.2). Equal velocity retention per second gives
  ``damping = (1 - (1 - drag)^(60/90)) / 0.2``, clamped to [0, 1].
* ``angle_restoration.stiffness`` from ``stiffness``: VRM adds ``stiffness·dt`` metres
  towards the rest direction to the tail every frame, i.e. an angular acceleration
  ``ω² = stiffness / (L·dt_vrm)`` per radian of deviation. MagicaCloth's restoration moves
  the segment by about ``3·0.2·value`` of its angle per step (three iterations, ref §D.6)
  and keeps ``velocity_attenuation`` (0.8) of that as velocity, i.e. ``ω² ≈ 0.48·value /
  dt_mc²``. Equal ω² gives ``value = stiffness·dt_mc² / (0.48·L·dt_vrm)``, clamped to [0, 1],
  flat over depth (VRM has one stiffness per joint, no depth curve).
* ``gravity`` from ``gravityPower``: chosen so the static sag angle of a segment matches.
  In VRM gravity and stiffness are both displacements per frame, so a segment rests where
  their sum is radial: ``θ = atan(gravityPower / stiffness)`` below its rest direction
  (for a horizontal rest direction and any L, drag or frame rate); in MagicaCloth it is ``θ ≈ g / (ω²·L)``, so
  ``g = θ·ω²_mc·L`` with the (possibly clamped) ω² of the chosen restoration value, clamped
  to [0, 20] m/s². With no stiffness, ``g = gravityPower / dt_vrm``.
* ``gravity_direction`` = ``gravityDir`` (converted to Unity axes by the caller).
* ``radius`` = ``hitRadius`` (flat over depth).
* ``root_rotation`` = ``rotational_interpolation`` = 1: a VRM joint turns fully towards its
  tail (ref §E.2 with t = 1 makes every bone point at its children).
* ``angle_limit.use`` = false, ``tether``/``distance`` defaults (VRM keeps bone lengths
  exactly; MagicaCloth's distance constraint at stiffness 1 does the same),
  ``inertia.world_inertia`` = ``local_inertia`` = 1 (VRM feels all of the character's motion).
* ``center`` (VRM's simulation space node) → ``inertia.anchor`` with ``anchor_inertia`` 0:
  motion of the center is not felt — the closest MagicaCloth2 counterpart.

No counterpart: VRM's per-joint parameter variation along a chain is averaged (a note says
so); VRM 1.0 ``inside`` colliders (MagicaCloth2 only pushes particles *out*) are skipped;
VRM has no friction (``collider_collision.friction`` stays at MagicaCloth's 0.05).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

VRM_FRAME_RATE = 60.0     # VRM springs step once per rendered frame; 60 Hz assumed
MC_STEP_RATE = 90.0       # MagicaCloth2 default simulation frequency (ref §A.5)
RESTORE_GAIN = 3 * 0.2 * 0.8   # 3 iterations x table factor 0.2 x velocity attenuation 0.8
GRAVITY_MAX = 20.0


@dataclass
class MappedParameters:
    """Dotted-key overrides for ``params.resolve_parameters`` plus what was approximated."""

    parameters: dict
    notes: list[str] = field(default_factory=list)


def map_spring_parameters(stiffness: float, gravity_power: float, gravity_dir, drag_force: float,
                          hit_radius: float, segment_length: float, center: str | None = None,
                          vrm_rate: float = VRM_FRAME_RATE, mc_rate: float = MC_STEP_RATE) -> MappedParameters:
    """Apply the module's rule to one chain's VRM parameters (Unity-axis ``gravity_dir``)."""
    notes = []
    dt_vrm, dt_mc = 1.0 / vrm_rate, 1.0 / mc_rate
    drag = min(max(float(drag_force), 0.0), 1.0)
    damping = (1.0 - (1.0 - drag) ** (vrm_rate / mc_rate)) / 0.2
    if damping > 1.0:
        notes.append(f"dragForce {drag_force:g} needs damping {damping:.3g} > 1: clamped to 1 (MagicaCloth damps at most 20%/step)")
    damping = min(max(damping, 0.0), 1.0)

    length = max(float(segment_length), 1e-4)
    omega2_vrm = max(float(stiffness), 0.0) / (length * dt_vrm)
    restore = omega2_vrm * dt_mc * dt_mc / RESTORE_GAIN
    if restore > 1.0:
        notes.append(f"stiffness {stiffness:g} over {length:.3g} m segments needs restoration {restore:.3g} > 1: clamped to 1")
    restore = min(max(restore, 0.0), 1.0)
    omega2_mc = RESTORE_GAIN * restore / (dt_mc * dt_mc)

    power = max(float(gravity_power), 0.0)
    if stiffness > 0.0:
        gravity = (power / stiffness) * omega2_mc * length
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
        "angle_restoration.use": restore > 0.0,
        "angle_restoration.stiffness": {"value": round(restore, 9), "use_curve": False},
        "angle_restoration.velocity_attenuation": 0.8,
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
    return MappedParameters(parameters, notes)
