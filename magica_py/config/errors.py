"""Configuration errors: every problem of a file, each with its document path and line.

A scene file is checked completely before anything is built, and every problem found is
reported together (a user fixing a file should not have to rerun once per typo). Each
problem is an :class:`Issue`:

* ``path``: where in the document, written the way a user reads it:
  ``cloths[1].parameters.damping``, ``rigs[0].bones[3].parent``; ``""`` is the document root;
* ``message``: what was wrong and what was expected (``expected a number in [0, 1], got 1.5``);
* ``line``: 1-based line in the YAML file when known (from ``yaml.compose`` nodes), or None
  for values that came from a ``--set`` override or were generated.

:class:`ConfigError` carries the file and the issues; ``str()`` gives the report the CLI
prints (no traceback)::

    configs/bad.yaml: 2 errors
      configs/bad.yaml:14: cloths[0].preset: unknown preset 'tial' (did you mean 'tail'?) ...
      configs/bad.yaml:20: colliders[1].sphere.radius: expected a number >= 0.001, got -0.1
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Iterable


@dataclass(frozen=True)
class Issue:
    """One problem in a scene document."""

    path: str
    message: str
    line: int | None = None

    def format(self, source: str | None) -> str:
        where = source or "<scene>"
        if self.line is not None:
            where = f"{where}:{self.line}"
        if self.path:
            return f"{where}: {self.path}: {self.message}"
        return f"{where}: {self.message}"


class ConfigError(ValueError):
    """A scene file (or its overrides) that cannot be used; lists every problem found."""

    def __init__(self, source: str | None, issues: Iterable[Issue]):
        self.source = source
        self.issues: list[Issue] = list(issues)
        super().__init__(self.report())

    def report(self) -> str:
        n = len(self.issues)
        head = f"{self.source or '<scene>'}: {n} error{'s' if n != 1 else ''}"
        return "\n".join([head] + ["  " + issue.format(self.source) for issue in self.issues])

    def __str__(self) -> str:
        return self.report()

    def __reduce__(self):
        # rebuilt from its arguments, not from ``args``: an error raised on a Dask worker
        # (or in a multiprocessing pool) must reach the caller as itself
        return (type(self), (self.source, self.issues), self.__dict__)

    def paths(self) -> list[str]:
        """The document paths of all issues (handy in tests)."""
        return [issue.path for issue in self.issues]


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest choice, or ``""`` when none is close."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def format_path(parts: Iterable[str | int]) -> str:
    """``("cloths", 1, "parameters", "damping")`` -> ``cloths[1].parameters.damping``."""
    out = ""
    for part in parts:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out
