"""Typed readers for document values that record every problem instead of stopping at one.

``Checker`` is the toolbox the schema (``schema.py``) and the cross-reference pass
(``load.py``) use. Each reader takes the parent mapping, the key and the parent path, returns
the converted value (or the default when the key is missing), and on a bad value records an
:class:`Issue` and returns the default, so validation goes on and reports everything at once.
Numbers refuse bools (``true`` is not 1) and non-finite values (``.nan``, ``.inf``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from magica_py.config.document import Document
from magica_py.config.errors import ConfigError, Issue, did_you_mean, format_path

REQUIRED = object()  # default marker: the key must be present


@dataclass(frozen=True)
class Range:
    """Numeric bounds; ``*_open`` makes a bound exclusive."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False

    def contains(self, x: float) -> bool:
        if self.low is not None and (x <= self.low if self.low_open else x < self.low):
            return False
        if self.high is not None and (x >= self.high if self.high_open else x > self.high):
            return False
        return True

    def describe(self) -> str:
        if self.low is not None and self.high is not None:
            return f"in {'(' if self.low_open else '['}{self.low:g}, {self.high:g}{')' if self.high_open else ']'}"
        if self.low is not None:
            return f"{'>' if self.low_open else '>='} {self.low:g}"
        if self.high is not None:
            return f"{'<' if self.high_open else '<='} {self.high:g}"
        return ""


ANY = Range()
POSITIVE = Range(0.0, low_open=True)
NON_NEGATIVE = Range(0.0)


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _type_name(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a bool"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, str):
        return "text"
    return "a number" if isinstance(value, (int, float)) else type(value).__name__


class Checker:
    """Collects issues for one document (see the module docstring)."""

    def __init__(self, doc: Document):
        self.doc = doc
        self.issues: list[Issue] = []

    # -- reporting
    def error(self, path: tuple, message: str) -> None:
        override = self.doc.override_of(path)
        if override is not None:
            message += f" (from --set {override})"
        self.issues.append(Issue(format_path(path), message, self.doc.line(path)))

    def raise_if_any(self) -> None:
        if self.issues:  # in file order; --set and generated problems last; each problem once
            # (an entry that generates several, e.g. from_vrm cloths, reports a shared mistake once)
            unique = list({(i.path, i.message, i.line): i for i in self.issues}.values())
            issues = sorted(unique, key=lambda i: (i.line is None, i.line or 0))
            raise ConfigError(self.doc.source, issues)

    # -- structure
    def mapping(self, value, path: tuple, allowed, *, what: str = "a mapping") -> dict | None:
        """``value`` as a dict whose keys are all in ``allowed`` (unknown keys are reported)."""
        if value is None:
            return {}
        if not isinstance(value, dict):
            self.error(path, f"expected {what}, got {_type_name(value)} {_show(value)}")
            return None
        allowed = list(allowed)
        for key in value:
            if key not in allowed:
                self.error(path + (key,), f"unknown key {key!r}{did_you_mean(key, allowed)}; "
                                          f"expected one of: {', '.join(allowed)}")
        return value

    def sequence(self, m: dict, key: str, path: tuple, *, min_length: int = 0) -> list:
        """m[key] as a list (missing = empty); a single mapping is not silently wrapped."""
        value = m.get(key)
        if value is None:
            if min_length:
                self.error(path + (key,), f"is required: expected a list of at least {min_length} entries")
            return []
        if not isinstance(value, list):
            self.error(path + (key,), f"expected a list, got {_type_name(value)} {_show(value)}")
            return []
        if len(value) < min_length:
            self.error(path + (key,), f"expected at least {min_length} entries, got {len(value)}")
        return value

    def required(self, m: dict, key: str, path: tuple, expected: str) -> bool:
        if m.get(key) is None:
            self.error(path + (key,) if key in m else path, f"missing {key!r}: expected {expected}")
            return False
        return True

    def exactly_one(self, m: dict, keys, path: tuple, *, required: bool = True) -> str | None:
        """The one key of ``keys`` present in ``m`` (None when absent and not required)."""
        present = [k for k in keys if m.get(k) is not None]  # null = absent (e.g. --set scene.fps=null)
        if len(present) > 1:
            self.error(path + (present[1],), f"give only one of {', '.join(keys)}; found {', '.join(present)}")
            return present[0]
        if not present:
            if required:
                self.error(path, f"expected one of {', '.join(keys)}")
            return None
        return present[0]

    # -- scalars
    def number(self, m: dict, key: str, path: tuple, default=REQUIRED, rng: Range = ANY,
               *, integer: bool = False, units: str = ""):
        if key not in m or m[key] is None:
            if default is REQUIRED:
                self.error(path if key not in m else path + (key,),
                           f"missing {key!r}: expected {'an integer' if integer else 'a number'} {rng.describe()}".rstrip())
                return None
            return default
        raw = m[key]
        where = path + (key,)
        expected = ("an integer" if integer else "a number") + (" " + rng.describe() if rng.describe() else "")
        expected += f" {units}" if units else ""
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            self.error(where, f"expected {expected}, got {_type_name(raw)} {_show(raw)}")
            return None if default is REQUIRED else default
        if not math.isfinite(raw):
            self.error(where, f"expected a finite number, got {raw}")
            return None if default is REQUIRED else default
        if integer and raw != int(raw):
            self.error(where, f"expected {expected}, got {raw}")
            return None if default is REQUIRED else default
        if not rng.contains(raw):
            self.error(where, f"expected {expected}, got {raw:g}")
            return None if default is REQUIRED else default
        return int(raw) if integer else float(raw)

    def integer(self, m, key, path, default=REQUIRED, rng: Range = ANY):
        return self.number(m, key, path, default, rng, integer=True)

    def boolean(self, m: dict, key: str, path: tuple, default=REQUIRED):
        if key not in m or m[key] is None:
            if default is REQUIRED:
                self.error(path, f"missing {key!r}: expected true or false")
                return None
            return default
        raw = m[key]
        if not isinstance(raw, bool):
            self.error(path + (key,), f"expected true or false, got {_type_name(raw)} {_show(raw)}")
            return default if default is not REQUIRED else None
        return raw

    def text(self, m: dict, key: str, path: tuple, default=REQUIRED, *, what: str = "text"):
        if key not in m or m[key] is None:
            if default is REQUIRED:
                self.error(path if key not in m else path + (key,), f"missing {key!r}: expected {what}")
                return None
            return default
        raw = m[key]
        if not isinstance(raw, str) or not raw.strip():
            self.error(path + (key,), f"expected {what}, got {_type_name(raw)} {_show(raw)}")
            return default if default is not REQUIRED else None
        return raw.strip()

    def choice(self, m: dict, key: str, path: tuple, choices, default=REQUIRED):
        """A case-insensitive enum value, returned lower-case."""
        value = self.text(m, key, path, default, what="one of " + ", ".join(choices))
        if value is None or value is default:
            return value
        low = value.lower().replace("-", "_")
        if low not in choices:
            self.error(path + (key,), f"unknown value {value!r}{did_you_mean(low, choices)}; "
                                      f"expected one of: {', '.join(choices)}")
            return default if default is not REQUIRED else None
        return low

    def names(self, m: dict, key: str, path: tuple, *, min_length: int = 0) -> list[str]:
        """A list of names (a single name is accepted as a one-element list)."""
        raw = m.get(key)
        if isinstance(raw, str):
            raw = [raw]
            m = dict(m, **{key: raw})
        items = self.sequence(m, key, path, min_length=min_length)
        out = []
        for i, item in enumerate(items):
            if not isinstance(item, str) or not item.strip():
                self.error(path + (key, i), f"expected a name, got {_type_name(item)} {_show(item)}")
            else:
                out.append(item.strip())
        return out

    # -- vectors
    def vector(self, m: dict, key: str, path: tuple, size: int = 3, default=REQUIRED,
               rng: Range = ANY, *, nonzero: bool = False, what: str = ""):
        if key not in m or m[key] is None:
            if default is REQUIRED:
                self.error(path, f"missing {key!r}: expected {what or f'a list of {size} numbers'}")
                return None
            return default
        raw = m[key]
        where = path + (key,)
        if not isinstance(raw, list) or len(raw) != size:
            shape = "[x, y, z]" if size == 3 else "[x, y, z, w]" if size == 4 else f"{size} numbers"
            self.error(where, f"expected {what or shape} (a list of {size} numbers), got {_show(raw)}")
            return None if default is REQUIRED else default
        out = []
        bad = False  # every bad element is reported, not only the first
        for i, x in enumerate(raw):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                self.error(where + (i,), f"expected a number, got {_type_name(x)} {_show(x)}")
            elif not math.isfinite(x):
                self.error(where + (i,), f"expected a finite number, got {x}")
            elif not rng.contains(x):
                self.error(where + (i,), f"expected a number {rng.describe()}, got {x:g}")
            else:
                out.append(float(x))
                continue
            bad = True
        if bad:
            return None if default is REQUIRED else default
        if nonzero and math.sqrt(sum(x * x for x in out)) < 1e-9:
            self.error(where, f"expected a non-zero {what or 'vector'}, got {raw}")
            return None if default is REQUIRED else default
        return tuple(out)

    def direction(self, m: dict, key: str, path: tuple, default=REQUIRED):
        """A non-zero 3-vector, returned normalized."""
        v = self.vector(m, key, path, 3, default, nonzero=True, what="direction [x, y, z]")
        if v is None or v is default:
            return v
        n = math.sqrt(sum(x * x for x in v))
        return tuple(x / n for x in v)

    def rotation(self, m: dict, path: tuple, *, rotation_key: str = "rotation", euler_key: str = "euler",
                 default=(0.0, 0.0, 0.0, 1.0)):
        """A unit quaternion (x, y, z, w) from ``rotation`` (quaternion) or ``euler`` (degrees,
        Unity's Quaternion.Euler order: Z, then X, then Y); at most one of the two."""
        kind = self.exactly_one(m, (rotation_key, euler_key), path, required=False)
        if kind is None:
            return default
        if kind == rotation_key:
            q = self.vector(m, rotation_key, path, 4, None, what="quaternion [x, y, z, w]")
            if q is None:
                return default
            n = math.sqrt(sum(x * x for x in q))
            if n < 1e-6:
                self.error(path + (rotation_key,), f"zero-length quaternion {list(m[rotation_key])}: "
                                                   "expected a rotation [x, y, z, w], e.g. [0, 0, 0, 1]")
                return default
            return tuple(x / n for x in q)
        e = self.vector(m, euler_key, path, 3, None, what="Euler angles [x, y, z] in degrees")
        return default if e is None else euler_to_quaternion(e)


def euler_to_quaternion(euler_degrees) -> tuple[float, float, float, float]:
    """Unity's Quaternion.Euler (via the math3d kernel helper)."""
    from magica_py.kernels.math3d import q_from_euler_degrees

    return tuple(float(c) for c in q_from_euler_degrees(*map(float, euler_degrees)))
