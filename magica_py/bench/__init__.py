"""Speed against error, converged references and the hard-case stability suite (docs/BENCHMARKS.md, docs/STABILITY.md).

* ``metrics``: stretch, root distance, collider penetration, speeds, energy, settling,
  trajectory errors (numpy over recorded runs);
* ``reference``: references (11520 Hz, checked against 23040 and 5760 Hz) and the windows
  where they resolve an error; the fitted convergence order;
* ``variants``: ``Variant`` (scene + parameters + frequency + fps) and the instrumented run;
* ``numpy_baseline``: the single-tail step as a user would write it in plain numpy;
* ``report``: markdown / CSV tables and the Pareto plot;
* ``cli``: ``magica-py bench`` and ``magica-py stability``.
"""
