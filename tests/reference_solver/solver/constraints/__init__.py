"""Constraint maths (``solve_*``: tuples in, corrections out) and their per-team kernels.

Each module holds one constraint of docs/solver.md §D: the maths is written once in a ``solve_*``
function that returns corrections without applying them (Bender's init_/solve_ split), and a
``*_team`` kernel walks one team's particles in index order (Gauss-Seidel, §D.0) and applies
them. The frame driver (``solver/frame.py``) calls the ``*_team`` kernels.
"""
