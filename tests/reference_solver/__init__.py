"""The per-team solver as it was before the lane form (issue 15), kept as a test-only oracle.

``reference_solver.solver.system.ClothSystem`` runs a scene team by team with the per-team
kernels; ``tests/test_lane_equivalence.py`` and ``benchmarks/port_check.py`` compare the lane
form against it bit for bit. It is frozen: the package does not import it.
"""
