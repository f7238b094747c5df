"""magica_py: MagicaCloth2-style BoneCloth secondary motion in Python + numba.

Importing the package configures numba's on-disk cache before numba is imported (see
``_configure_numba_cache``); everything else is imported lazily so that ``magica-py --help``
stays fast.
"""
from __future__ import annotations

import hashlib
import os
import pathlib
import sys

__version__ = "0.1.0"


def _configure_numba_cache() -> None:
    """Point NUMBA_CACHE_DIR at a folder keyed by a hash of this package's sources.

    numba keys its cache on the kernel's own file only, so a kernel whose helper lives in
    another module keeps returning stale results after the helper changes (tech-notes §7).
    Keying the whole cache folder on the package's sources makes any edit start a fresh
    cache. A user-set NUMBA_CACHE_DIR is respected.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    root = pathlib.Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(base, "magica_py", "numba-" + digest.hexdigest()[:16])
    if "numba" in sys.modules:  # numba read its config already: make it read it again
        from numba.core import config

        config.reload_config()


_configure_numba_cache()
