"""The Gaussian-process stress surrogate: log p99 interpolated between the grid's values.

Scale invariance: every length is a multiple of the dermal thickness t_d and the materials
carry no length, so at fixed dimensionless factors the stresses do not depend on t_d.
``dermal_thickness_mm`` is therefore no input, and rows that differ only in it are
replicates, averaged into one point; their spread is the noise floor (solver and mesh noise).

Symmetry: the wound and its layers are mirror-symmetric across and along the wound, and the
stiff axis at orientation t is a line (t and t + 180 deg are one axis), so every result is an
even, 180-degree-periodic function of t, that is a function of cos 2t: the orientation enters
as cos 2t (`ANGLE_INPUTS`), which puts the grid's 0, 45 and 90 deg at 1, 0 and -1 and a wound
between them where its stress lies between theirs.

One GP per (wound shape, skin type, stage) group. Inputs: the shape's other model columns
that vary in training, positive factors log-transformed, the orientation as cos 2t, each
scaled to [0, 1] over the training values (the cylinder offset linearly). Kernel: constant x
Matern(nu=2.5, one length per input) + white noise, on targets normalised per group. The
hyperparameters maximise the log marginal likelihood (scikit-learn, L-BFGS-B from one fixed
start) on at most `HYPER_POINTS` of the group's points; the posterior conditions on all.

Saved as JSON (`GP_SURROGATE_FORMAT`, no pickle): the inputs' transforms and per group the
hyperparameters, the training inputs and targets. Loading refits the posterior with the
hyperparameters fixed (one Cholesky per group) and checks every field (one-line errors).
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from ..core.errors import AnalysisError
from ..core.versions import GP_SURROGATE_FORMAT
from .settings import SHAPE_CODES

__all__ = [
    "ANGLE_INPUTS",
    "HYPER_POINTS",
    "KERNEL",
    "GPSurrogate",
    "InputScale",
    "cos_2t",
    "fit_gp",
]

# Columns that are no GP input: the group's keys, and t_d (scale invariance).
NOT_INPUTS = ("wound_shape", "skin_type", "stage", "dermal_thickness_mm")
# Positive factors, interpolated in their logarithm.
LOG_INPUTS = frozenset(
    {"subcutis_thickness_factor", "patch_size_factor", "wound_width_factor",
     "wound_depth_factor", "wound_length_factor", "mesh_size_factor"}
)  # fmt: skip
# Angles (degrees) of an axis, interpolated in cos 2t (the module docstring's symmetry).
ANGLE_INPUTS = frozenset({"orientation_deg"})
# Points per group the hyperparameters are fitted on (a seeded subsample beyond it).
HYPER_POINTS = 256
# Fewer points than this in a group train no GP.
MIN_POINTS = 5
KERNEL = "constant * Matern(nu=2.5, one length scale per input) + white noise"
_BOUNDS = {"constant": (1e-3, 1e3), "length": (1e-2, 1e2), "noise": (1e-6, 1.0)}
_SHAPE_NAMES = {code: name for name, code in SHAPE_CODES.items()}

GroupKey = tuple[str, float, int]  # wound shape, skin c (kPa), stage


class InputScale(NamedTuple):
    """A shape's GP inputs: model columns, log flags and the [low, high] mapped onto [0, 1]."""

    names: tuple[str, ...]
    log: tuple[bool, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """Raw column values (rows x ``names``) -> scaled inputs."""
        angle = np.array([n in ANGLE_INPUTS for n in self.names])
        v = np.where(angle, cos_2t(raw), raw)
        v = np.where(np.asarray(self.log), np.log(np.where(self.log, v, 1.0)), v)
        return (v - np.asarray(self.low)) / (np.asarray(self.high) - np.asarray(self.low))


def cos_2t(deg: Any) -> np.ndarray:
    """cos 2t of angles t in degrees: the coordinate every result is a function of."""
    return np.cos(np.radians(2.0 * np.asarray(deg, dtype=np.float64)))


class Group(NamedTuple):
    """One group's GP: hyperparameters, training points (raw inputs, mean log stress,
    replicate counts), target normalisation, within-replicate SD, the fitted posterior."""

    key: GroupKey
    skin_type: str
    hyper: dict[str, Any]
    x: np.ndarray
    y: np.ndarray
    replicates: np.ndarray
    y_mean: float
    y_std: float
    replicate_sd: float | None
    posterior: Any


def _kernel(constant: float, lengths: Sequence[float], noise: float, fixed: bool) -> Any:
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    b = {k: "fixed" if fixed else v for k, v in _BOUNDS.items()}
    return ConstantKernel(constant, b["constant"]) * Matern(
        list(lengths), b["length"], nu=2.5
    ) + WhiteKernel(noise, b["noise"])


def _posterior(hyper: Mapping[str, Any], z: np.ndarray, t: np.ndarray) -> Any:
    """The GP conditioned on (``z``, ``t``) with fixed hyperparameters (one Cholesky)."""
    from sklearn.gaussian_process import GaussianProcessRegressor

    k = _kernel(hyper["constant"], hyper["length_scales"], hyper["noise"], fixed=True)
    return GaussianProcessRegressor(k, optimizer=None).fit(z, t)


def _hyperparameters(z: np.ndarray, t: np.ndarray, seed: int) -> dict[str, Any]:
    """Constant, length scales and noise maximising the log marginal likelihood."""
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor

    if len(z) > HYPER_POINTS:
        pick = np.sort(np.random.default_rng(seed).choice(len(z), HYPER_POINTS, replace=False))
        z, t = z[pick], t[pick]
    gp = GaussianProcessRegressor(_kernel(1.0, [1.0] * z.shape[1], 1e-2, fixed=False))
    with warnings.catch_warnings():  # a length scale at its bound: an input without effect
        warnings.simplefilter("ignore", ConvergenceWarning)
        k = gp.fit(z, t).kernel_
    return {
        "constant": float(k.k1.k1.constant_value),
        "length_scales": [float(v) for v in np.atleast_1d(k.k1.k2.length_scale)],
        "noise": float(k.k2.noise_level),
    }


def shape_inputs(X: np.ndarray, features: Sequence[str], code: float) -> InputScale:
    """The inputs of the shape ``code``: its columns that vary over its rows of ``X``."""
    sub = X[X[:, list(features).index("wound_shape")] == code]
    cols: list[tuple[str, bool, float, float]] = []
    for j, name in enumerate(features):
        v = cos_2t(sub[:, j]) if name in ANGLE_INPUTS else sub[:, j]
        if name in NOT_INPUTS or not np.isfinite(v).all() or np.ptp(v) == 0:
            continue
        is_log = name in LOG_INPUTS and bool((v > 0).all())
        t = np.log(v) if is_log else v
        cols.append((name, is_log, float(t.min()), float(t.max())))
    if not cols:
        raise AnalysisError(
            f"stress surrogate (gp): no input varies over the {_SHAPE_NAMES[code]} rows"
        )
    names, log, low, high = zip(*cols)
    return InputScale(names, log, low, high)


def average_replicates(
    x: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
    """Rows with equal inputs (they differ in t_d only) -> unique inputs, mean target,
    count; and the within-replicate sum of squares and its degrees of freedom."""
    frame = pd.DataFrame(x).assign(_y=y)
    g = frame.groupby(list(range(x.shape[1])), sort=True)["_y"]
    mean, count = g.mean(), g.count()
    ss = float(((frame["_y"] - g.transform("mean")) ** 2).sum())
    xs = np.array(mean.index.tolist(), dtype=np.float64).reshape(len(mean), x.shape[1])
    return xs, mean.to_numpy(np.float64), count.to_numpy(np.int64), ss, int((count - 1).sum())


def _group(key: GroupKey, skin: str, x: np.ndarray, y: np.ndarray, scale: InputScale,
           seed: int) -> Group:  # fmt: skip
    """Average the replicates, fit the hyperparameters, condition on every point."""
    xs, ys, n, ss, dof = average_replicates(x, y)
    if len(xs) < MIN_POINTS:
        raise AnalysisError(
            f"stress surrogate (gp): {len(xs)} points for {key[0]} / skin {skin} / stage "
            f"{key[2]}; at least {MIN_POINTS} are needed"
        )
    mu, sd = float(ys.mean()), float(ys.std()) or 1.0
    z, t = scale.apply(xs), (ys - mu) / sd
    hyper = _hyperparameters(z, t, seed)
    rep = math.sqrt(ss / dof) if dof else None
    return Group(key, skin, hyper, xs, ys, n, mu, sd, rep, _posterior(hyper, z, t))


class GPSurrogate:
    """Per-group Gaussian processes behind the common interface (`surrogate.Surrogate`)."""

    kind = "gp"
    continuous = True

    def __init__(self, features: Sequence[str], scales: Mapping[str, InputScale],
                 groups: Sequence[Group]) -> None:  # fmt: skip
        self._features = list(features)
        self.scales = dict(scales)
        self.groups = {g.key: g for g in groups}

    @property
    def features(self) -> list[str]:
        return list(self._features)

    def _keys(self, X: np.ndarray) -> list[GroupKey]:
        col = {n: X[:, self._features.index(n)] for n in ("wound_shape", "skin_type", "stage")}
        return [
            (_SHAPE_NAMES.get(float(s), "?"), float(c), int(t))
            for s, c, t in zip(col["wound_shape"], col["skin_type"], col["stage"])
        ]

    def predict_log(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean of log p99 (log kPa) and predictive SD (noise included) per row."""
        X = np.asarray(X, dtype=np.float64)
        mean, sd = np.empty(len(X)), np.empty(len(X))
        keys = self._keys(X)
        distinct = sorted(set(keys))
        pos = {k: j for j, k in enumerate(distinct)}
        code = np.array([pos[k] for k in keys], dtype=np.int64)
        for j, key in enumerate(distinct):
            g = self.groups.get(key)
            if g is None:
                raise AnalysisError(
                    f"the GP surrogate has no group for {key[0]} / skin c={key[1]:g} kPa / "
                    f"stage {key[2]} (not in its training rows)"
                )
            idx = np.flatnonzero(code == j)
            scale = self.scales[key[0]]
            raw = X[np.ix_(idx, np.array([self._features.index(n) for n in scale.names]))]
            m, s = g.posterior.predict(scale.apply(raw), return_std=True)
            mean[idx], sd[idx] = m * g.y_std + g.y_mean, s * g.y_std
        return mean, sd

    def summary(self) -> dict[str, Any]:
        """The fit in numbers for metrics.json: points, noise floor, hyperparameters."""
        gs = list(self.groups.values())
        pts = np.array([len(g.y) for g in gs])
        ss = sum(g.replicate_sd**2 * int((g.replicates - 1).sum()) for g in gs if g.replicate_sd)
        dof = sum(int((g.replicates - 1).sum()) for g in gs)
        fitted = [math.sqrt(g.hyper["noise"]) * g.y_std for g in gs]
        lengths = {
            shape: {
                n: float(np.median([g.hyper["length_scales"][i] for g in gs if g.key[0] == shape]))
                for i, n in enumerate(sc.names)
            }
            for shape, sc in self.scales.items()
        }
        return {
            "kernel": KERNEL,
            "groups": len(gs),
            "points": int(pts.sum()),
            "rows": int(sum(int(g.replicates.sum()) for g in gs)),
            "points_per_group": {
                "min": int(pts.min()),
                "median": float(np.median(pts)),
                "max": int(pts.max()),
            },  # fmt: skip
            "hyperparameter_points": HYPER_POINTS,
            "inputs": {
                s: [
                    f"log {n}" if lg else f"cos 2 {n}" if n in ANGLE_INPUTS else n
                    for n, lg in zip(sc.names, sc.log)
                ]
                for s, sc in self.scales.items()
            },  # fmt: skip
            "noise_floor_log_sd": math.sqrt(ss / dof) if dof else None,
            "noise_floor_from": "rows that differ only in dermal_thickness_mm (pooled SD of log stress)",
            "fitted_noise_log_sd": {"median": float(np.median(fitted)), "max": float(max(fitted))},
            "length_scales_median": lengths,
        }

    def to_doc(self) -> dict[str, Any]:
        """The JSON document of `to_bytes`."""
        return {
            "format": GP_SURROGATE_FORMAT,
            "kernel": KERNEL,
            "features": self._features,
            "shapes": {s: sc._asdict() for s, sc in self.scales.items()},
            "groups": [
                {
                    "wound_shape": g.key[0], "skin_type": g.skin_type, "skin_c_kPa": g.key[1],
                    "stage": g.key[2], **g.hyper, "y_mean": g.y_mean, "y_std": g.y_std,
                    "inputs": g.x.tolist(), "log_p99": g.y.tolist(),
                    "replicates": g.replicates.tolist(), "replicate_sd_log": g.replicate_sd,
                }
                for g in self.groups.values()
            ],
        }  # fmt: skip

    def to_bytes(self) -> bytes:
        return (json.dumps(self.to_doc(), allow_nan=False) + "\n").encode()

    @classmethod
    def read(cls, path: Path) -> GPSurrogate:
        """Load and check ``path`` and refit each group's posterior (`AnalysisError`, one
        line naming the file and the field, for a damaged file)."""
        try:
            doc = json.loads(Path(path).read_text())
        except (OSError, ValueError, RecursionError):
            raise AnalysisError(f"{path}: missing or unreadable GP surrogate") from None
        if not isinstance(doc, dict) or doc.get("format") != GP_SURROGATE_FORMAT:
            raise AnalysisError(f"{path}: not a woundsweep GP surrogate ({GP_SURROGATE_FORMAT})")
        try:
            return cls.from_doc(doc)
        except _Damaged as err:
            raise AnalysisError(f"{path}: {err}") from None

    @classmethod
    def from_doc(cls, doc: Mapping[str, Any]) -> GPSurrogate:
        features = doc.get("features")
        if not (isinstance(features, list) and all(isinstance(f, str) for f in features)
                and {"wound_shape", "skin_type", "stage"} <= set(features)):  # fmt: skip
            raise _Damaged("a malformed 'features'")
        scales = _read_scales(doc.get("shapes"), features)
        groups = doc.get("groups")
        if not isinstance(groups, list) or not groups:
            raise _Damaged("a malformed 'groups'")
        return cls(features, scales, [_read_group(i, g, scales) for i, g in enumerate(groups)])


class _Damaged(ValueError):
    """A field of a GP surrogate file that cannot be read."""


def _numbers(v: Any, n: int | None = None, positive: bool = False) -> np.ndarray | None:
    """``v`` as finite floats (``n`` of them, all > 0 if ``positive``), else None."""
    if not isinstance(v, list) or (n is not None and len(v) != n):
        return None
    if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        return None
    a = np.asarray(v, dtype=np.float64)
    ok = np.isfinite(a).all() and (not positive or (a > 0).all())
    return a if ok else None


def _read_scales(v: Any, features: list[str]) -> dict[str, InputScale]:
    if not isinstance(v, dict) or not v:
        raise _Damaged("a malformed 'shapes'")
    return {shape: _read_scale(shape, s, features) for shape, s in v.items()}


def _read_scale(shape: Any, s: Any, features: list[str]) -> InputScale:
    bad = _Damaged(f"a malformed 'shapes' entry {shape!r}")
    if shape not in SHAPE_CODES or not isinstance(s, dict):
        raise bad
    names, log = s.get("names"), s.get("log")
    if not (isinstance(names, list) and names and all(n in features for n in names)):
        raise bad
    if not (isinstance(log, list) and len(log) == len(names)
            and all(isinstance(b, bool) for b in log)):  # fmt: skip
        raise bad
    low, high = _numbers(s.get("low"), len(names)), _numbers(s.get("high"), len(names))
    if low is None or high is None or not (high > low).all():
        raise bad
    return InputScale(tuple(names), tuple(log), tuple(low.tolist()), tuple(high.tolist()))


def _read_group(i: int, g: Any, scales: Mapping[str, InputScale]) -> Group:
    """One saved group, checked, with its posterior refitted."""
    bad = _Damaged(f"a malformed 'groups' entry {i}")
    if not isinstance(g, dict) or g.get("wound_shape") not in scales:
        raise bad
    scale = scales[g["wound_shape"]]
    d = len(scale.names)
    y = _numbers(g.get("log_p99"))
    rows = g.get("inputs")
    x = [_numbers(r, d) for r in rows] if isinstance(rows, list) else [None]
    reps = _numbers(g.get("replicates"), len(rows) if isinstance(rows, list) else -1, True)
    lengths = _numbers(g.get("length_scales"), d, positive=True)
    scalars = _numbers([g.get(k) for k in ("constant", "noise", "y_std", "y_mean", "skin_c_kPa")])
    stage = g.get("stage")
    if (y is None or lengths is None or scalars is None or reps is None or not y.size
            or any(r is None for r in x) or len(x) != len(y) or (scalars[:3] <= 0).any()
            or not isinstance(stage, int) or isinstance(stage, bool)
            or not isinstance(g.get("skin_type"), str)):  # fmt: skip
        raise bad
    xs = np.array(x, dtype=np.float64).reshape(len(y), d)
    if (xs[:, list(scale.log)] <= 0).any():
        raise bad
    hyper = {"constant": float(g["constant"]), "length_scales": lengths.tolist(),
             "noise": float(g["noise"])}  # fmt: skip
    mu, sd = float(g["y_mean"]), float(g["y_std"])
    try:
        post = _posterior(hyper, scale.apply(xs), (y - mu) / sd)
    except (np.linalg.LinAlgError, ValueError):
        raise _Damaged(f"group {i}: its posterior cannot be refitted") from None
    rep = g.get("replicate_sd_log")
    key = (g["wound_shape"], float(g["skin_c_kPa"]), stage)
    rep_sd = float(rep) if isinstance(rep, (int, float)) else None
    return Group(key, g["skin_type"], hyper, xs, y, reps.astype(np.int64), mu, sd, rep_sd, post)


def fit_gp(
    X: np.ndarray, y: np.ndarray, features: Sequence[str], skins: Mapping[float, str], seed: int
) -> GPSurrogate:
    """One GP per (shape, skin, stage) group of the rows ``X`` (model columns ``features``)
    with log stress ``y``; ``skins``: skin c (kPa) -> name."""
    features = list(features)
    col = {n: X[:, features.index(n)] for n in ("wound_shape", "skin_type", "stage")}
    scales = {_SHAPE_NAMES[c]: shape_inputs(X, features, c) for c in np.unique(col["wound_shape"])}
    keys = sorted({(_SHAPE_NAMES[s], float(c), int(t)) for s, c, t in zip(*col.values())})
    groups = []
    for i, key in enumerate(keys):
        sel = ((col["wound_shape"] == SHAPE_CODES[key[0]]) & (col["skin_type"] == key[1])
               & (col["stage"] == key[2]))  # fmt: skip
        scale = scales[key[0]]
        raw = X[np.ix_(sel, np.array([features.index(n) for n in scale.names]))]
        groups.append(_group(key, skins.get(key[1], f"{key[1]:g}"), raw, y[sel], scale,
                             seed + i))  # fmt: skip
    return GPSurrogate(features, scales, groups)
