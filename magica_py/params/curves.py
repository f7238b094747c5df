"""Depth curves (docs/solver.md §0.3, MagicaCloth2's CurveSerializeData).

A curve parameter is a scalar ``value`` times an optional Unity AnimationCurve over depth
t in [0, 1]. The simulation never evaluates the AnimationCurve: it gets a 16-entry table
``S[i] = curve(i / 15) * value`` (or ``value`` everywhere when the curve is off) and
interpolates it piecewise-linearly (``evaluate_curve``).

YAML forms accepted by ``Curve.parse``:

* ``0.2`` — flat (useCurve off);
* ``{value: 0.2, curve: [1.0, 0.2]}`` — linear from 1.0 at depth 0 to 0.2 at depth 1, on
  (the ``CurveSerializeData(value, start, end)`` constructor: both ends clamped to [0, 1]);
* ``{value: 0.1, keys: [[t, v, in_slope, out_slope], ...]}`` — Unity Hermite keys, on;
* ``use_curve: false`` in either mapping keeps the keys but turns the curve off.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from magica_py.jit import kernel

CURVE_SAMPLES = 16

Key = tuple[float, float, float, float]  # (time, value, in_slope, out_slope)


@dataclass(frozen=True)
class Curve:
    value: float
    keys: tuple[Key, ...] = ((0.0, 1.0, 0.0, 0.0), (1.0, 1.0, 0.0, 0.0))
    use_curve: bool = False

    @staticmethod
    def flat(value: float) -> "Curve":
        return Curve(float(value))

    @staticmethod
    def linear(value: float, start: float, end: float, use_curve: bool = True) -> "Curve":
        """``CurveSerializeData(value, start, end)``: a linear curve, ends clamped to [0, 1]."""
        s = min(max(float(start), 0.0), 1.0)
        e = min(max(float(end), 0.0), 1.0)
        slope = e - s
        return Curve(float(value), ((0.0, s, slope, slope), (1.0, e, slope, slope)), use_curve)

    @staticmethod
    def hermite(value: float, k0: tuple[float, float], k1: tuple[float, float], use_curve: bool = True) -> "Curve":
        """Two keys at t=0 and t=1 given as (value, out_slope) and (value, in_slope) (§F.2 notation)."""
        return Curve(float(value), ((0.0, float(k0[0]), 0.0, float(k0[1])), (1.0, float(k1[0]), float(k1[1]), 0.0)), use_curve)

    def with_value(self, value: float) -> "Curve":
        return Curve(float(value), self.keys, self.use_curve)

    def shape(self, t: float) -> float:
        """Unity AnimationCurve.Evaluate (cubic Hermite between keys, clamped outside)."""
        keys = self.keys
        if t <= keys[0][0]:
            return keys[0][1]
        if t >= keys[-1][0]:
            return keys[-1][1]
        for k0, k1 in zip(keys[:-1], keys[1:]):
            if k0[0] <= t <= k1[0]:
                dt = k1[0] - k0[0]
                if dt <= 0.0:
                    return k1[1]
                s = (t - k0[0]) / dt
                m0 = k0[3] * dt
                m1 = k1[2] * dt
                s2, s3 = s * s, s * s * s
                return ((2 * s3 - 3 * s2 + 1) * k0[1] + (s3 - 2 * s2 + s) * m0
                        + (s3 - s2) * m1 + (-2 * s3 + 3 * s2) * k1[1])
        return keys[-1][1]

    @property
    def samples(self) -> np.ndarray:
        """The 16-entry job table ``S`` (§0.3 ConvertFloatArray), read-only."""
        if self.use_curve:
            table = np.array([self.shape(i / 15.0) * self.value for i in range(CURVE_SAMPLES)])
        else:
            table = np.full(CURVE_SAMPLES, self.value, dtype=np.float64)
        table.flags.writeable = False
        return table

    def evaluate(self, depth: float) -> float:
        return float(evaluate_curve(self.samples, float(depth)))

    def to_yaml(self):
        if not self.use_curve:
            return self.value
        return {"value": self.value, "keys": [list(k) for k in self.keys]}

    @staticmethod
    def parse(raw, where: str) -> "Curve":
        """Parse a YAML curve value; raise ValueError naming ``where`` when malformed."""
        if isinstance(raw, Curve):
            return raw
        if isinstance(raw, bool):
            raise ValueError(f"{where}: expected a number or a curve mapping, got a boolean")
        if isinstance(raw, (int, float)):
            return Curve.flat(_finite(raw, where))
        if not isinstance(raw, dict):
            raise ValueError(f"{where}: expected a number or a mapping {{value, curve|keys, use_curve}}, got {type(raw).__name__}")
        unknown = set(raw) - {"value", "curve", "keys", "use_curve"}
        if unknown:
            raise ValueError(f"{where}: unknown curve keys {sorted(unknown)} (expected value, curve, keys, use_curve)")
        if "value" not in raw:
            raise ValueError(f"{where}.value: missing (the curve's scale)")
        value = _finite(raw["value"], f"{where}.value")
        use = raw.get("use_curve", True)
        if not isinstance(use, bool):
            raise ValueError(f"{where}.use_curve: expected true or false")
        if "curve" in raw and "keys" in raw:
            raise ValueError(f"{where}: give either 'curve' [start, end] or 'keys', not both")
        if "curve" in raw:
            c = raw["curve"]
            if not (isinstance(c, list) and len(c) == 2):
                raise ValueError(f"{where}.curve: expected [start, end] (values at depth 0 and 1)")
            return Curve.linear(value, _finite(c[0], f"{where}.curve[0]"), _finite(c[1], f"{where}.curve[1]"), use)
        if "keys" in raw:
            ks = raw["keys"]
            if not isinstance(ks, list) or len(ks) < 1:
                raise ValueError(f"{where}.keys: expected a list of [time, value, in_slope, out_slope]")
            keys = []
            for j, k in enumerate(ks):
                if not (isinstance(k, list) and len(k) == 4):
                    raise ValueError(f"{where}.keys[{j}]: expected [time, value, in_slope, out_slope]")
                keys.append(tuple(_finite(x, f"{where}.keys[{j}]") for x in k))
            times = [k[0] for k in keys]
            if times != sorted(times):
                raise ValueError(f"{where}.keys: key times must increase")
            return Curve(value, tuple(keys), use)
        return Curve(value, Curve.flat(0).keys, False if "use_curve" not in raw else use)


def _finite(x, where: str) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise ValueError(f"{where}: expected a number, got {x!r}")
    if not math.isfinite(float(x)):
        raise ValueError(f"{where}: expected a finite number, got {x!r}")
    return float(x)


@kernel
def evaluate_curve(table, depth):
    """``DataUtility.EvaluateCurve`` (MC2EvaluateCurve): piecewise-linear in the 16 samples."""
    d = depth
    sd = 0.0 if d < 0.0 else (1.0 if d > 1.0 else d)
    i = int(sd * 15.0)
    u = (d - i / 15.0) * 15.0
    j = i + 1 if i + 1 < 15 else 15
    return table[i] + (table[j] - table[i]) * u


@kernel
def evaluate_curve_clamp01(table, depth):
    """``MC2EvaluateCurveClamp01``: evaluate_curve saturated to [0, 1]."""
    v = evaluate_curve(table, depth)
    if v < 0.0:
        return 0.0
    if v > 1.0:
        return 1.0
    return v
