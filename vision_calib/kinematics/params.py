"""Named parameter sets: the one place that packs parameters (by name) into vectors.

A :class:`ParameterSet` is immutable. It holds, for every geometric parameter of a model
(robot + camera/target mounting), its name (``"d3"``, ``"beta3"``, ``"T_flange_cam.tx"``,
``"h4.L"``, ``"q0_2"``), its nominal value (SI: m or rad), its kind (``"length"``,
``"angle"``, or ``"coefficient"``: dimensionless, e.g. the nuisance coefficients of
:mod:`~vision_calib.identify.nuisance`; used for scaling and unit conversion) and whether it is free (identified) or
fixed. Vectors ``x`` are always *full* (all parameters, in ``names`` order); solvers pick
the free entries with :attr:`free_index`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Iterable, Mapping

import numpy as np

from ..errors import ParameterError

#: default scale (typical size of an error) per kind, used to scale Jacobian columns
DEFAULT_SCALE = {"length": 1e-3, "angle": 1e-3, "coefficient": 1.0}  # 1 mm, 1 mrad, 1
#: parameter kinds
KINDS = ("length", "angle", "coefficient")


@dataclass(frozen=True)
class ParameterSet:
    """Named parameters of a model.

    names: (n,) unique names. nominal: (n,) float64, SI units. kinds: (n,) "length"|"angle"|"coefficient".
    free: (n,) bool, True = identified. scale: (n,) typical deviation (m or rad), used as
    column scaling and as the default prior std for the EKF.
    """

    names: tuple[str, ...]
    nominal: np.ndarray
    kinds: tuple[str, ...]
    free: np.ndarray
    scale: np.ndarray
    _index: Mapping[str, int] = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        n = len(self.names)
        if len(set(self.names)) != n:
            dup = sorted({x for x in self.names if self.names.count(x) > 1})
            raise ParameterError(f"duplicate parameter names: {dup}")
        nominal = np.array(self.nominal, dtype=float).reshape(-1)
        free = np.array(self.free, dtype=bool).reshape(-1)
        scale = np.array(self.scale, dtype=float).reshape(-1)
        for arr, what in ((nominal, "nominal"), (free, "free"), (scale, "scale")):
            if arr.shape != (n,):
                raise ParameterError(f"ParameterSet.{what} has shape {arr.shape}, expected ({n},)")
        if len(self.kinds) != n:
            raise ParameterError(f"ParameterSet.kinds has {len(self.kinds)} entries, expected {n}")
        bad = [k for k in self.kinds if k not in KINDS]
        if bad:
            raise ParameterError(f"unknown parameter kinds {sorted(set(bad))} (expected one of {', '.join(KINDS)})")
        for arr in (nominal, free, scale):
            arr.setflags(write=False)
        object.__setattr__(self, "nominal", nominal)
        object.__setattr__(self, "free", free)
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "kinds", tuple(self.kinds))
        object.__setattr__(self, "_index", {nm: i for i, nm in enumerate(self.names)})

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_lists(cls, names, nominal, kinds, free=None, scale=None) -> "ParameterSet":
        """Build from plain lists; free defaults to all True, scale to DEFAULT_SCALE by kind."""
        n = len(names)
        if free is None:
            free = np.ones(n, dtype=bool)
        if scale is None:
            scale = [DEFAULT_SCALE.get(k, 1.0) for k in kinds]
        return cls(tuple(names), np.asarray(nominal, float), tuple(kinds), np.asarray(free, bool), np.asarray(scale, float))

    def __len__(self) -> int:
        return len(self.names)

    # ------------------------------------------------------------------ lookup
    def index(self, name: str) -> int:
        """Position of ``name`` in the full vector; ParameterError listing close names if unknown."""
        try:
            return self._index[name]
        except KeyError:
            import difflib

            close = difflib.get_close_matches(name, self.names, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise ParameterError(f"unknown parameter name {name!r}{hint}; known: {', '.join(self.names)}") from None

    def indices(self, names: Iterable[str]) -> np.ndarray:
        """Positions (k,) int of several names."""
        return np.array([self.index(n) for n in names], dtype=int)

    def mask(self, names: Iterable[str]) -> np.ndarray:
        """Boolean mask (n,) selecting ``names``."""
        m = np.zeros(len(self), dtype=bool)
        m[self.indices(list(names))] = True
        return m

    @property
    def free_index(self) -> np.ndarray:
        """Positions (n_free,) of free parameters in the full vector."""
        return np.flatnonzero(self.free)

    @property
    def free_names(self) -> tuple[str, ...]:
        return tuple(self.names[i] for i in self.free_index)

    @property
    def n_free(self) -> int:
        return int(self.free.sum())

    # ------------------------------------------------------------------ modification (returns copies)
    def with_free(self, names: Iterable[str], free: bool = True) -> "ParameterSet":
        """Copy with ``names`` set free (or fixed when free=False)."""
        f = self.free.copy()
        f[self.indices(list(names))] = free
        return replace(self, free=f)

    def fix(self, names: Iterable[str]) -> "ParameterSet":
        """Copy with ``names`` fixed (kept at their value, not identified)."""
        return self.with_free(names, False)

    def only_free(self, names: Iterable[str]) -> "ParameterSet":
        """Copy where exactly ``names`` are free."""
        return replace(self, free=self.mask(names))

    def with_nominal(self, values) -> "ParameterSet":
        """Copy with a new nominal vector (n,) or a {name: value} mapping applied."""
        if isinstance(values, Mapping):
            v = self.nominal.copy()
            for k, val in values.items():
                v[self.index(k)] = float(val)
        else:
            v = np.asarray(values, float).reshape(-1)
        return replace(self, nominal=v)

    def with_scale(self, values: Mapping[str, float]) -> "ParameterSet":
        s = self.scale.copy()
        for k, val in values.items():
            s[self.index(k)] = float(val)
        return replace(self, scale=s)

    def concat(self, other: "ParameterSet") -> "ParameterSet":
        """Parameters of self followed by those of other (names must not clash)."""
        return ParameterSet(
            self.names + other.names,
            np.concatenate([self.nominal, other.nominal]),
            self.kinds + other.kinds,
            np.concatenate([self.free, other.free]),
            np.concatenate([self.scale, other.scale]),
        )

    # ------------------------------------------------------------------ packing
    def values(self, x=None) -> dict[str, float]:
        """{name: value} of a full vector x (n,) (nominal if None)."""
        x = self.nominal if x is None else np.asarray(x, float)
        return {n: float(v) for n, v in zip(self.names, x)}

    def vector(self, values: Mapping[str, float] | None = None, base=None) -> np.ndarray:
        """Full vector (n,) from ``base`` (default nominal) with named entries replaced."""
        x = (self.nominal if base is None else np.asarray(base, float)).copy()
        for k, val in (values or {}).items():
            x[self.index(k)] = float(val)
        return x

    def expand(self, x_free, base=None) -> np.ndarray:
        """Full vector (n,) from free values (n_free,), fixed ones taken from base (default nominal)."""
        x = (self.nominal if base is None else np.asarray(base, float)).copy()
        x[self.free_index] = x_free
        return x
