"""BoneCloth parameters: the table (docs/solver.md §F.1), the 11 presets (§F.2) and their resolution.

``resolve_parameters(preset, overrides, where)`` returns a ``ClothParameters``: a frozen
mapping from every dotted key of ``PARAMETERS`` to its value (floats, ``Curve`` objects,
bools, enum strings, 3-tuples, transform names or None; limits as floats with -1 meaning
"no limit"). Overrides may be nested (``{inertia: {world_inertia: 0.5}}``) or dotted
(``{"inertia.world_inertia": 0.5}``). Every problem raises ``ParameterError`` whose
``path`` is the document path of the offending value (``cloths[1].parameters.damping``).
"""
from __future__ import annotations

import difflib
import functools
import math
import re
from collections.abc import Mapping

from magica_py.params.curves import Curve, evaluate_curve, evaluate_curve_clamp01
from magica_py.params.presets import PRESETS
from magica_py.params.table import INTEGER_PARAMETERS, LIMIT_ENABLED_DEFAULTS, PARAMETER_DEFS, PARAMETERS, ParameterDef

__all__ = [
    "Curve", "ClothParameters", "ParameterError", "PARAMETERS", "PARAMETER_DEFS", "PRESETS",
    "default_parameters", "preset_names", "resolve_parameters", "parse_value", "evaluate_curve", "evaluate_curve_clamp01",
]

_OFF_WORDS = ("off", "false", "none", "disabled")


class ParameterError(ValueError):
    """A bad parameter value: ``path`` locates it in the document, ``message`` says what was expected."""

    def __init__(self, path: str, message: str):
        super().__init__(f"{path}: {message}")
        self.path = path
        self.message = message

    def __reduce__(self):  # unpickles as itself (Dask workers, multiprocessing)
        return (type(self), (self.path, self.message), self.__dict__)


class ClothParameters(Mapping):
    """Immutable mapping dotted key → value, complete (every key of the table is present)."""

    __slots__ = ("_values",)

    def __init__(self, values: dict):
        object.__setattr__(self, "_values", dict(values))

    def __getitem__(self, key):
        return self._values[key]

    def __iter__(self):
        return iter(self._values)

    def __len__(self):
        return len(self._values)

    def __setattr__(self, name, value):
        raise AttributeError("ClothParameters is immutable: use with_changes()")

    def __reduce__(self):
        # pickled by value (snapshots and batch jobs cross process boundaries); the default
        # protocol would go through the blocked __setattr__
        return (ClothParameters, (self._values,))

    def __repr__(self):
        return f"ClothParameters({len(self)} keys)"

    def __eq__(self, other):
        return isinstance(other, ClothParameters) and self._values == other._values

    def __hash__(self):
        return hash(tuple(sorted((k, repr(v)) for k, v in self._values.items())))

    def with_changes(self, changes: Mapping, where: str = "parameters") -> "ClothParameters":
        """A copy with some keys changed (validated like YAML overrides)."""
        values = dict(self._values)
        for key, raw in flatten_overrides(changes, where).items():
            values[key] = parse_value(PARAMETERS[key], raw, f"{where}.{key}", values.get(key))
        return ClothParameters(values)

    def limit(self, key: str) -> float:
        """A limit parameter's value, -1 when disabled (what the simulation receives)."""
        return float(self._values[key])

    def to_dict(self) -> dict:
        """YAML-friendly nested dict of every value."""
        out: dict = {}
        for key, value in self._values.items():
            node = out
            parts = key.split(".")
            for p in parts[:-1]:
                node = node.setdefault(p, {})
            if isinstance(value, Curve):
                value = value.to_yaml()
            elif isinstance(value, tuple):
                value = list(value)
            elif PARAMETERS[key].kind == "limit" and value < 0:
                value = False
            node[parts[-1]] = value
        return out


def preset_names() -> list[str]:
    return sorted(PRESETS)


def _normalize_preset_name(name: str) -> str:
    """'ShortHair', 'short-hair', 'Short Hair' and 'short_hair' all name the same preset."""
    snake = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name.strip())
    return re.sub(r"[\s\-]+", "_", snake).lower()


def flatten_overrides(overrides: Mapping | None, where: str) -> dict:
    """Nested or dotted overrides → {dotted key: raw value}; unknown keys raise with a did-you-mean."""
    flat: dict = {}
    if overrides is None:
        return flat
    if not isinstance(overrides, Mapping):
        raise ParameterError(where, f"expected a mapping of parameter names to values, got {type(overrides).__name__}")

    def visit(node: Mapping, prefix: str, path: str):
        for name, value in node.items():
            if not isinstance(name, str):
                raise ParameterError(path, f"parameter names must be strings, got {name!r}")
            key = f"{prefix}{name}"
            sub_path = f"{path}.{name}"
            if key in PARAMETERS:
                flat[key] = value
            elif isinstance(value, Mapping) and any(k.startswith(key + ".") for k in PARAMETERS):
                visit(value, key + ".", sub_path)
            else:
                raise ParameterError(sub_path, f"unknown parameter {key!r}{_did_you_mean(key)}")

    visit(overrides, "", where)
    return flat


def _did_you_mean(key: str) -> str:
    leaves = {k.rsplit(".", 1)[-1]: k for k in PARAMETERS}
    match = difflib.get_close_matches(key, list(PARAMETERS), n=1, cutoff=0.6)
    if not match:
        leaf = difflib.get_close_matches(key.rsplit(".", 1)[-1], list(leaves), n=1, cutoff=0.6)
        match = [leaves[leaf[0]]] if leaf else []
    return f" (did you mean {match[0]!r}?)" if match else ""


def _number(raw, where: str) -> float:
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise ParameterError(where, f"expected a number, got {raw!r}")
    value = float(raw)
    if not math.isfinite(value):
        raise ParameterError(where, f"expected a finite number, got {raw!r}")
    return value


def _check_range(d: ParameterDef, value: float, where: str) -> float:
    if d.lo is not None and value < d.lo or d.hi is not None and value > d.hi:
        raise ParameterError(where, f"{value:g} is out of range [{d.lo:g}, {d.hi:g}]{' ' + d.units if d.units else ''}")
    return value


def parse_value(d: ParameterDef, raw, where: str, current=None):
    """Validate and convert one raw (YAML) value for parameter ``d``."""
    kind = d.kind
    if kind == "float":
        value = _number(raw, where)
        if d.key in INTEGER_PARAMETERS and value != int(value):
            raise ParameterError(where, f"expected a whole number, got {raw!r}")
        return _check_range(d, value, where)
    if kind == "curve":
        if isinstance(raw, (int, float)) and not isinstance(raw, bool) and isinstance(current, Curve) and current.use_curve:
            # a bare number on a curve parameter rescales the curve, like the inspector's value field
            curve = current.with_value(_number(raw, where))
        else:
            try:
                curve = Curve.parse(raw, where)
            except ValueError as exc:
                path, _, message = str(exc).partition(": ")
                raise ParameterError(path, message) from None
        _check_range(d, curve.value, where)
        return curve
    if kind == "limit":
        if raw is None or raw is False or (isinstance(raw, str) and raw.lower() in _OFF_WORDS):
            return -1.0
        if raw is True or (isinstance(raw, str) and raw.lower() in ("on", "true")):
            return LIMIT_ENABLED_DEFAULTS[d.key]
        if isinstance(raw, Mapping):
            unknown = set(raw) - {"use", "value"}
            if unknown:
                raise ParameterError(where, f"unknown keys {sorted(unknown)} (expected use, value)")
            use = raw.get("use", True)
            if not isinstance(use, bool):
                raise ParameterError(f"{where}.use", "expected true or false")
            value = _check_range(d, _number(raw.get("value", LIMIT_ENABLED_DEFAULTS[d.key]), f"{where}.value"), f"{where}.value")
            return value if use else -1.0
        return _check_range(d, _number(raw, where), where)
    if kind == "bool":
        if not isinstance(raw, bool):
            raise ParameterError(where, f"expected true or false, got {raw!r}")
        return raw
    if kind == "enum":
        if not isinstance(raw, str) or raw.strip().lower() not in d.choices:
            raise ParameterError(where, f"expected one of {', '.join(d.choices)}, got {raw!r}")
        return raw.strip().lower()
    if kind == "vector3":
        if not (isinstance(raw, (list, tuple)) and len(raw) == 3):
            raise ParameterError(where, f"expected [x, y, z], got {raw!r}")
        v = tuple(_number(x, f"{where}[{i}]") for i, x in enumerate(raw))
        n = math.sqrt(sum(x * x for x in v))
        return tuple(x / n for x in v) if n > 1e-6 else (0.0, 0.0, 0.0)
    if kind == "transform":
        if raw is not None and not isinstance(raw, str):
            raise ParameterError(where, f"expected a transform name or null, got {raw!r}")
        return raw
    raise AssertionError(f"unknown parameter kind {kind}")


def _defaults(gravity_direction=None) -> dict:
    values = {}
    for d in PARAMETER_DEFS:
        values[d.key] = parse_value(d, d.default, f"<default {d.key}>")
    if gravity_direction is not None:
        values["gravity_direction"] = parse_value(PARAMETERS["gravity_direction"], list(gravity_direction), "scene.gravity")
    return values


@functools.lru_cache(maxsize=1)
def default_parameters() -> ClothParameters:
    """Every parameter at its default of the table (``params/table.py``, the one place the
    defaults are written), parsed as a scene's values are: what a parameter mapping that
    lacks a key stands for (the solver's job data, the build's switches)."""
    return ClothParameters(_defaults())


def resolve_parameters(preset: str | None = None, overrides: Mapping | None = None,
                       where: str = "parameters", *, preset_where: str | None = None,
                       gravity_direction=None) -> ClothParameters:
    """Defaults, then the preset's values, then the overrides; everything validated."""
    values = _defaults(gravity_direction)
    if preset is not None:
        if not isinstance(preset, str):
            raise ParameterError(preset_where or "preset", f"expected a preset name, got {preset!r}")
        name = _normalize_preset_name(preset)
        if name not in PRESETS:
            close = difflib.get_close_matches(name, list(PRESETS), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ParameterError(preset_where or "preset", f"unknown preset {preset!r}{hint}; presets: {', '.join(sorted(PRESETS))}")
        for key, value in PRESETS[name].items():
            values[key] = value if isinstance(value, Curve) else parse_value(PARAMETERS[key], value, f"preset {name}.{key}")
    for key, raw in flatten_overrides(overrides, where).items():
        values[key] = parse_value(PARAMETERS[key], raw, f"{where}.{key}", values.get(key))
    return ClothParameters(values)
