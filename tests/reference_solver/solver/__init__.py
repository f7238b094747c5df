"""The BoneCloth solver (§A.3-§A.7, §C-§G of docs/solver.md): MagicaCloth2's
LATE_UPDATE frame for every cloth of a scene in one numba call.

* ``system.ClothSystem`` — the LATE_UPDATE system (build, state, parameters, runtime API);
* ``frame.simulate_frame`` — the frame kernel (stage order of §D.0);
* ``state`` / ``layout`` / ``parameters`` — the SoA tables (state, concatenated model, job
  parameters); ``center``, ``step``, ``colliders``, ``constraints/*``, ``display``,
  ``rotations``, ``writeback``, ``guards`` — the stages.

``attach(player, scene)`` builds a ``ClothSystem`` for ``scene.cloths`` and registers it in
``player``'s LATE_UPDATE phase (and the restored bones in its RESTORE registry).
"""
from __future__ import annotations


def attach(player, scene, parallel=None):
    """Build the cloth system of ``scene`` and attach it to ``player``; returns the system.
    ``parallel``: None follows the scene's ``threads`` setting, True / False force numba's
    threads / one thread (``system.choose_threads``)."""
    from reference_solver.solver.system import ClothSystem

    return ClothSystem(scene.hierarchy, scene.cloths, scene.colliders, scene.settings, parallel=parallel,
                       wind=getattr(scene, "wind", ())).attach(player, scene)


__all__ = ["attach"]
