"""Model files: ``model_<scheme>.json`` (the XGBoost booster) and ``model_<scheme>_meta.json``.

The metadata holds what prediction needs besides the booster: the feature order, the shape
and skin codes, the per-shape feature ranges of the training rows, the trained stages and
the quantile edges (kPa). It is tagged with `MODEL_FORMAT`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from ..errors import AnalysisError
from ..fsutil import atomic_write_bytes
from .settings import MODEL_FORMAT

if TYPE_CHECKING:
    from .fitting import SchemeFit

__all__ = ["LoadedModel", "json_bytes", "load_model", "resolve_model_path", "save_model"]


class LoadedModel(NamedTuple):
    """A saved booster and its metadata (feature ranges, codes, quantile edges)."""

    path: Path
    booster: Any
    meta: dict[str, Any]


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


def resolve_model_path(path: str | Path, scheme: str | None = None) -> Path:
    """A model file, or the model of ``scheme`` (default: geometry, else random) in a run or analysis dir."""
    p = Path(path)
    if p.is_file():
        return p
    if not p.is_dir():
        raise AnalysisError(f"{p}: no such model file or run directory")
    for d in (p / "analysis", p):
        for s in [scheme] if scheme else ["geometry", "random"]:
            if (d / f"model_{s}.json").is_file():
                return d / f"model_{s}.json"
    raise AnalysisError(f"{p}: no trained model found (run `woundsweep analyze` first)")


def load_model(path: str | Path, scheme: str | None = None) -> LoadedModel:
    """Load ``model_<scheme>.json`` and the ``model_<scheme>_meta.json`` beside it."""
    import xgboost as xgb

    model_path = resolve_model_path(path, scheme)
    meta_path = model_path.with_name(model_path.stem + "_meta.json")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, ValueError):
        raise AnalysisError(f"{meta_path}: missing or unreadable model metadata") from None
    if meta.get("format") != MODEL_FORMAT:
        raise AnalysisError(f"{meta_path}: not a woundsweep model description")
    booster = xgb.Booster()
    try:
        booster.load_model(str(model_path))
    except xgb.core.XGBoostError:
        raise AnalysisError(f"{model_path}: unreadable XGBoost model") from None
    return LoadedModel(model_path, booster, meta)
