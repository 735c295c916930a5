"""Model files: ``model_<scheme>.json`` (the XGBoost booster) and ``model_<scheme>_meta.json``;
beside them the stress surrogate (``surrogate.json``: the booster, or the Gaussian processes
of `interpolant` as JSON, by the metadata's ``surrogate`` kind; + ``surrogate_meta.json``)
and the failure model (``failure_model.json``, absent when too few jobs failed, + its
metadata).

The classifier's metadata holds what prediction needs besides the booster: the feature
order, the shape and skin codes, the per-shape feature ranges and grid values of the
training rows, the trained stages and the quantile edges (kPa); it is tagged with
`MODEL_FORMAT`. The surrogate's holds its ranges and calibration scores (`SURROGATE_FORMAT`),
the failure model's its statement and the store's failure rate (`FAILURE_FORMAT`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from ..core.errors import AnalysisError
from ..core.fsutil import atomic_write_bytes
from ..core.layout import RunLayout
from ..core.versions import FAILURE_FORMAT, MODEL_FORMAT, SURROGATE_FORMAT

if TYPE_CHECKING:
    import xgboost as xgb

    from .failure import FailureFit
    from .fitting import SchemeFit
    from .regression import SurrogateFit
    from .surrogate import Surrogate

__all__ = [
    "FAILURE_STEM",
    "SURROGATE_STEM",
    "LoadedModel",
    "check_model",
    "json_bytes",
    "load_model",
    "resolve_model_path",
    "save_booster",
    "save_companions",
    "save_model",
]

SURROGATE_STEM = "surrogate"
FAILURE_STEM = "failure_model"


class LoadedModel(NamedTuple):
    """A saved classifier and its metadata; the surrogate and failure model found beside it.

    ``surrogate`` is a (`Surrogate`, metadata) pair and ``failure`` a (booster, metadata)
    pair, ``None`` where absent; a failure model without a booster has ``(None, metadata)``
    (its statement says why).
    """

    path: Path
    booster: xgb.Booster
    meta: dict[str, Any]
    surrogate: tuple[Any, dict[str, Any]] | None = None
    failure: tuple[Any, dict[str, Any]] | None = None


def json_bytes(obj: Any) -> bytes:
    """The JSON encoding of the analysis files (metrics, model metadata): strict, indented."""
    return (json.dumps(obj, indent=1, allow_nan=False) + "\n").encode()


def save_model(out_dir: Path, fit: SchemeFit) -> list[Path]:
    """Write the scheme's booster and metadata atomically; return both paths."""
    model_path = out_dir / f"model_{fit.scheme}.json"
    atomic_write_bytes(model_path, bytes(fit.trained.booster.save_raw("json")))
    meta_path = out_dir / f"model_{fit.scheme}_meta.json"
    atomic_write_bytes(meta_path, json_bytes(fit.meta))
    return [model_path, meta_path]


def save_booster(
    out_dir: Path, stem: str, booster: xgb.Booster | None, meta: dict[str, Any]
) -> list[Path]:
    """Write ``stem.json`` (unless ``booster`` is None) and ``stem_meta.json`` atomically."""
    paths = []
    if booster is not None:
        paths.append(out_dir / f"{stem}.json")
        atomic_write_bytes(paths[-1], bytes(booster.save_raw("json")))
    paths.append(out_dir / f"{stem}_meta.json")
    atomic_write_bytes(paths[-1], json_bytes(meta))
    return paths


def save_companions(out_dir: Path, surrogate: SurrogateFit, failure: FailureFit) -> list[Path]:
    """Write the stress surrogate and the failure model beside the classifiers."""
    paths = [out_dir / f"{SURROGATE_STEM}.json", out_dir / f"{SURROGATE_STEM}_meta.json"]
    atomic_write_bytes(paths[0], surrogate.model.to_bytes())
    atomic_write_bytes(paths[1], json_bytes(surrogate.meta))
    return paths + save_booster(out_dir, FAILURE_STEM, failure.booster, failure.meta)


def _read_booster(path: Path) -> xgb.Booster:
    import xgboost as xgb

    booster = xgb.Booster()
    try:
        booster.load_model(str(path))
    except xgb.core.XGBoostError:
        raise AnalysisError(f"{path}: unreadable XGBoost model") from None
    return booster


def _read_meta(path: Path, fmt: str, what: str) -> dict[str, Any]:
    try:
        meta = json.loads(path.read_text())
    except (OSError, ValueError, RecursionError):  # RecursionError: a deeply nested file
        raise AnalysisError(f"{path}: missing or unreadable model metadata") from None
    if not isinstance(meta, dict) or meta.get("format") != fmt:
        raise AnalysisError(f"{path}: not a woundsweep {what} description")
    return meta


def _read_surrogate(path: Path, meta: dict[str, Any]) -> Surrogate:
    """The surrogate of the kind its metadata names (the trees when it names none)."""
    from .interpolant import GPSurrogate
    from .surrogate import TreeSurrogate

    readers: dict[str, Callable[[Path], Surrogate]] = {
        "trees": lambda p: TreeSurrogate(_read_booster(p), nthread=1),
        "gp": GPSurrogate.read,
    }
    kind = meta.get("surrogate", "trees")
    if kind not in readers:
        raise AnalysisError(
            f"{path.with_name(SURROGATE_STEM + '_meta.json')}: a malformed 'surrogate'"
        )
    return readers[kind](path)


def _companion(directory: Path, stem: str, fmt: str, what: str) -> tuple[Any, dict] | None:
    meta_path = directory / f"{stem}_meta.json"
    if not meta_path.is_file():
        return None
    meta = _read_meta(meta_path, fmt, what)
    model_path = directory / f"{stem}.json"
    if stem == SURROGATE_STEM:
        if not model_path.is_file():  # a surrogate is always saved whole
            raise AnalysisError(f"{model_path}: missing (its metadata {meta_path.name} is there)")
        return _read_surrogate(model_path, meta), meta
    return (_read_booster(model_path) if model_path.is_file() else None), meta


def resolve_model_path(path: str | Path, scheme: str | None = None) -> Path:
    """A model file, or the model of ``scheme`` (default: geometry, else random) in a run or analysis dir."""
    p = Path(path)
    if p.is_file():
        return p
    if not p.is_dir():
        raise AnalysisError(f"{p}: no such model file or run directory")
    layout = RunLayout(p)
    for d in (layout.analysis_dir, p):
        for s in [scheme] if scheme else ["geometry", "random"]:
            if (d / f"model_{s}.json").is_file():
                return d / f"model_{s}.json"
    if not layout.manifest.is_file() and p != RunLayout(p.parent).analysis_dir:
        raise AnalysisError(
            f"{p}: not a run directory (no {layout.manifest.name}) and no model_<split>.json in it;"
            " give a run directory after `woundsweep analyze`, its analysis/ or a model file"
        )
    raise AnalysisError(f"{p}: no trained model found (run `woundsweep analyze {p}` first)")


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _span_map(v: Any) -> bool:
    """shape -> column -> [lo, hi] (numbers)."""
    return isinstance(v, dict) and all(
        isinstance(cols, dict)
        and all(
            isinstance(r, list) and len(r) == 2 and all(_number(x) for x in r)
            for r in cols.values()
        )
        for cols in v.values()
    )


def _levels_map(v: Any) -> bool:
    """shape -> column -> sorted grid values or null."""
    return isinstance(v, dict) and all(
        isinstance(cols, dict)
        and all(
            g is None or (isinstance(g, list) and all(_number(x) for x in g)) for g in cols.values()
        )
        for cols in v.values()
    )


def _strings(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


def _scores(v: Any) -> bool:
    """stage (digits) -> calibration scores (numbers)."""
    return isinstance(v, dict) and all(
        isinstance(k, str) and k.isdigit() and isinstance(x, list) and all(_number(y) for y in x)
        for k, x in v.items()
    )


def _problem(meta: dict[str, Any], checks: dict[str, Any]) -> str | None:
    for key, ok in checks.items():
        if key not in meta:
            return f"no {key!r}"
        if not ok(meta[key]):
            return f"a malformed {key!r}"
    return None


def check_model(model: LoadedModel) -> None:
    """Check every field `predict` reads in the model's files (`AnalysisError` naming the
    file and the field otherwise): a damaged file that keeps its format tag is one line."""
    meta = model.meta
    q = meta.get("quantiles")
    checks = {
        "scheme": lambda v: isinstance(v, str),
        "quantiles": lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 2,
        "features": lambda v: _strings(v) and "stage" in v,
        "stages": lambda v: isinstance(v, list) and bool(v) and all(isinstance(x, int) for x in v),
        "quantile_edges_kPa": lambda v: (
            isinstance(v, list)
            and len(v) == (q if isinstance(q, int) else -2) + 1
            and all(_number(x) for x in v)
        ),
        "skin_codes_c_kPa": lambda v: (
            isinstance(v, dict) and bool(v) and all(_number(x) for x in v.values())
        ),
        "ranges": _span_map,
        "levels": _levels_map,
    }
    problem = _problem(meta, checks)
    if problem:
        raise AnalysisError(f"{model.path.with_name(model.path.stem + '_meta.json')}: {problem}")
    if model.surrogate is not None:
        columns = model.surrogate[0].features  # the metadata's must be the model file's
        sur = {
            "calibration_scores_log": _scores,
            "features": lambda v: _strings(v) and v == columns,
            "ranges": _span_map,
        }
        problem = _problem(model.surrogate[1], sur)
        if problem:
            raise AnalysisError(f"{model.path.with_name(SURROGATE_STEM + '_meta.json')}: {problem}")
    if model.failure is not None:
        fail = {"statement": lambda v: isinstance(v, str)}
        if model.failure[0] is not None:
            fail["features"] = _strings
        problem = _problem(model.failure[1], fail)
        if problem:
            raise AnalysisError(f"{model.path.with_name(FAILURE_STEM + '_meta.json')}: {problem}")


def load_model(path: str | Path, scheme: str | None = None) -> LoadedModel:
    """Load ``model_<scheme>.json`` and the ``model_<scheme>_meta.json`` beside it."""
    model_path = resolve_model_path(path, scheme)
    meta = _read_meta(model_path.with_name(model_path.stem + "_meta.json"), MODEL_FORMAT, "model")
    d = model_path.parent
    return LoadedModel(
        model_path,
        _read_booster(model_path),
        meta,
        _companion(d, SURROGATE_STEM, SURROGATE_FORMAT, "stress surrogate"),
        _companion(d, FAILURE_STEM, FAILURE_FORMAT, "failure model"),
    )
