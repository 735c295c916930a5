"""Global sensitivity of the stress surrogate: Sobol first-order and total indices (SALib).

`sobol_indices` estimates the indices of any function of inputs on the unit cube (Saltelli
sampling on a scrambled Sobol sequence, Jansen / Saltelli 2010 estimators, SALib's
``sobol``). `surrogate_sobol` applies it to the surrogate's log p99 over the training
ranges, one input per `IMPORTANCE_GROUPS` entry: numeric parameters uniform over
[min, max] of the training rows, the wound shape, skin type and stage uniform over their
trained levels, and ``wound_depth`` uniform over the wedge's or excision's depth factor or the
cylinder aspect factor range, whichever applies to the sampled shape (oriented so that a larger
value is a deeper wound for all), the excision's length factor on excisions only. Inputs with a single trained
value are fixed. The grid's exclusions are not applied: the surrogate is evaluated on the
whole box.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from .settings import FEATURES, IMPORTANCE_GROUPS, SHAPE_CODES, SHAPE_FACTORS

if TYPE_CHECKING:
    import xgboost as xgb

    from .surrogate import Surrogate

__all__ = ["SobolInput", "sobol_indices", "surrogate_inputs", "surrogate_sobol"]


class SobolInput(NamedTuple):
    """One input: a range (``levels`` empty) or discrete ``levels``, each equally likely."""

    name: str
    low: float
    high: float
    levels: tuple[float, ...] = ()

    def scale(self, u: np.ndarray) -> np.ndarray:
        """Map uniform ``u`` in [0, 1] to this input's values."""
        if self.levels:
            k = np.minimum((u * len(self.levels)).astype(np.int64), len(self.levels) - 1)
            return np.asarray(self.levels, dtype=np.float64)[k]
        return self.low + u * (self.high - self.low)


def sobol_indices(
    func: Callable[[np.ndarray], np.ndarray], names: Sequence[str], n_base: int, seed: int
) -> dict[str, Any]:
    """S1 and ST (with 95 % bootstrap half-widths) of ``func`` over the unit cube ``[0, 1]^d``.

    ``func`` maps an (n, d) array of points to n outputs; it is called once, on
    ``n_base * (d + 2)`` points.
    """
    from SALib.analyze import sobol as analyze
    from SALib.sample import sobol as sample

    # Names as an array: SALib 1.5 hands them to pandas.unique, which refuses lists (pandas 3).
    problem = {
        "num_vars": len(names),
        "names": np.array(names, dtype=object),
        "bounds": [[0.0, 1.0]] * len(names),
    }
    U = sample.sample(problem, n_base, calc_second_order=False, seed=seed)
    Y = np.asarray(func(U), dtype=np.float64)
    # SALib seeds its bootstrap only for a truthy seed: map every seed to a nonzero one.
    boot = 2 * abs(int(seed)) + 1
    res = analyze.analyze(problem, Y, calc_second_order=False, num_resamples=100, seed=boot)
    out = {
        n: {
            "S1": float(res["S1"][i]),
            "S1_conf": float(res["S1_conf"][i]),
            "ST": float(res["ST"][i]),
            "ST_conf": float(res["ST_conf"][i]),
        }
        for i, n in enumerate(names)
    }
    return {
        "method": "Saltelli sampling, SALib sobol (Jansen / Saltelli 2010), 95% bootstrap",
        "base_samples": int(n_base),
        "evaluations": int(len(Y)),
        "output_variance": float(np.var(Y)),
        "indices": out,
        "ranking_total": sorted(out, key=lambda n: (-out[n]["ST"], n)),
    }


def _numeric(
    name: str, members: Sequence[str], meta: dict[str, Any], shape: str | None
) -> SobolInput:
    """One numeric input over the grid values of ``members`` (or their range if too many)."""
    shapes = [shape] if shape else list(meta["ranges"])
    spans = [meta["ranges"][s][m] for s in shapes for m in members if m in meta["ranges"][s]]
    levels = [v for s in shapes for m in members for v in meta["levels"].get(s, {}).get(m, [])]
    lo, hi = min(x[0] for x in spans), max(x[1] for x in spans)
    many = any(
        m in meta["ranges"][s] and m not in meta["levels"].get(s, {})
        for s in shapes
        for m in members
    )
    if many:
        return SobolInput(name, lo, hi)
    ordered = sorted(set(levels), reverse=members == ("wound_aspect_factor",))
    return SobolInput(name, lo, hi, tuple(ordered))


def surrogate_inputs(meta: dict[str, Any]) -> tuple[list[SobolInput], dict[str, float]]:
    """The varied inputs and the fixed ones (a single trained value), from `fit_surrogate` meta.

    A group none of whose members is a column of the surrogate, or was trained on (the
    excision's length factor in a store of trenches), is no input."""
    ranges = meta["ranges"]
    columns = set(meta.get("features", FEATURES))
    trained = {m for r in ranges.values() for m in r}
    cand: list[SobolInput] = []
    for group, members in IMPORTANCE_GROUPS.items():
        if not set(members) & columns:
            continue
        if group == "wound_shape":
            # Every trained shape has a code (the key never returns None).
            levels = tuple(SHAPE_CODES[s] for s in sorted(ranges, key=SHAPE_CODES.get))  # type: ignore[arg-type]
        elif group == "skin_type":
            levels = tuple(sorted(float(c) for c in meta["skin_levels_c_kPa"]))
        elif group == "stage":
            levels = tuple(float(s) for s in sorted(meta["stages"]))
        elif len(members) > 1:  # the shape-specific depth factor: mapped per shape later
            per_shape = _depth_inputs(meta).values()
            wide = any((len(c.levels) > 1) if c.levels else c.high > c.low for c in per_shape)
            cand.append(SobolInput(group, 0.0, 1.0 if wide else 0.0))
            continue
        else:
            if set(members) & trained:
                cand.append(_numeric(group, members, meta, None))
            continue
        cand.append(SobolInput(group, 0.0, 1.0, levels))
    varied = [c for c in cand if (len(c.levels) > 1 if c.levels else c.high > c.low)]
    fixed = {c.name: (c.levels[0] if c.levels else c.low) for c in cand if c not in varied}
    return varied, fixed


# Each shape's own depth column (a larger value is a deeper wound, except the cylinder's).
_DEPTH = {
    "wedge": "wound_depth_factor",
    "fusiform": "wound_depth_factor",
    "cylindrical": "wound_aspect_factor",
}


def _depth_inputs(meta: dict[str, Any]) -> dict[float, SobolInput]:
    """Shape code -> the input of its own depth column; a larger value is a deeper wound for
    every shape (the largest wedge or excision depth factor, the smallest cylinder offset:
    the axis sits at z = a w, so a larger a is shallower)."""
    return {
        SHAPE_CODES[s]: _numeric(_DEPTH[s], (_DEPTH[s],), meta, s)
        for s, r in meta["ranges"].items()
        if _DEPTH[s] in r
    }


def surrogate_function(
    predict: Callable[[np.ndarray], np.ndarray],
    inputs: Sequence[SobolInput],
    fixed: dict[str, float],
    meta: dict[str, Any],
) -> Callable[[np.ndarray], np.ndarray]:
    """Unit-cube points -> rows of the surrogate's columns -> ``predict`` (its log p99).

    A shape's own factors are set on the rows of that shape only (NaN on the others, as in
    training): the depth input per shape (`_depth_inputs`), the length factor on excisions."""
    depth = _depth_inputs(meta)
    features = list(meta.get("features", FEATURES))
    own = {f: s for s, fs in SHAPE_FACTORS.items() for f in fs if f not in _DEPTH.values()}

    def func(U: np.ndarray) -> np.ndarray:
        val = {c.name: c.scale(U[:, i]) for i, c in enumerate(inputs)}
        val.update({k: np.full(len(U), v) for k, v in fixed.items()})
        X = np.full((len(U), len(features)), np.nan)
        for j, f in enumerate(features):
            if f in val:
                X[:, j] = val[f]
                if f in own:
                    X[val["wound_shape"] != SHAPE_CODES[own[f]], j] = np.nan
        for code, c in depth.items():
            sel = val["wound_shape"] == code
            u = val["wound_depth"][sel]
            if not c.levels:  # a range: the cylinder's runs from its largest offset down
                u = u if c.name == "wound_depth_factor" else 1.0 - u
            X[sel, features.index(c.name)] = c.scale(u)
        return predict(X)

    return func


def surrogate_sobol(
    model: Surrogate | xgb.Booster, meta: dict[str, Any], n_base: int, seed: int,
    nthread: int = 2,
) -> dict[str, Any]:  # fmt: skip
    """Sobol indices of the surrogate's log p99 (its mean) over its training grid
    (`fit_surrogate` meta); ``model`` a `Surrogate` or a bare booster (``nthread`` threads)."""
    from .surrogate import as_surrogate

    sur = as_surrogate(model, nthread)
    inputs, fixed = surrogate_inputs(meta)
    func = surrogate_function(lambda X: sur.predict_log(X)[0], inputs, fixed, meta)
    out = sobol_indices(func, [c.name for c in inputs], n_base, seed)
    out["output"] = "log p99 von Mises (log kPa) of the stress surrogate"
    out["inputs"] = {
        c.name: ({"levels": list(c.levels)} if c.levels else {"range": [c.low, c.high]})
        for c in inputs
    }
    out["fixed"] = fixed
    return out
