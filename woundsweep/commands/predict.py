"""``woundsweep predict MODEL_OR_RUN_DIR --shape ... (all parameters)``: one wound's stress quantile."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import click

from ..clitypes import FiniteFloat

__all__ = ["cmd"]


# The Table 1 parameters given as numbers: option, manifest column, required, help.
_NUMERIC_PARAMS = (
    ("--dermal-thickness", "dermal_thickness_mm", True, "Epidermis + dermis thickness t_d (mm)."),
    ("--subcutis-thickness-factor", "subcutis_thickness_factor", True, "Subcutis thickness / t_d."),
    ("--patch-size-factor", "patch_size_factor", True, "Patch half-length / total thickness."),
    ("--wound-width-factor", "wound_width_factor", True, "Wound width / patch half-length."),
    ("--wound-depth-factor", "wound_depth_factor", False, "Wedge only: depth / total thickness."),
    (
        "--wound-aspect-factor",
        "wound_aspect_factor",
        False,
        "Cylindrical only: axis offset / width.",
    ),
    ("--mesh-size-factor", "mesh_size_factor", True, "Mesh size factor (larger = finer)."),
    (
        "--orientation",
        "orientation_deg",
        True,
        "Stiff axis angle to x, 0 = across the wound (deg).",
    ),
)


def _numeric_params(f: Callable[..., None]) -> Callable[..., None]:
    """One float option per `_NUMERIC_PARAMS` entry, in that order, named by its column."""
    for flag, column, required, text in reversed(_NUMERIC_PARAMS):
        f = click.option(
            flag, column, type=FiniteFloat(), required=required, default=None, help=text
        )(f)
    return f


@click.command("predict")
@click.argument("model", type=click.Path(path_type=Path))
@click.option(
    "--shape", required=True, type=click.Choice(["cylindrical", "wedge"]), help="Wound shape."
)
@_numeric_params
@click.option("--skin-type", required=True, help="Skin type name, e.g. soft, normal, stiff.")
@click.option(
    "--stage", "stages", type=click.IntRange(1, 6), multiple=True, help="Stage(s) [all trained]."
)
@click.option("--split", "scheme", type=click.Choice(["random", "geometry"]), default=None,
              help="Which model of a run directory [geometry if present].")  # fmt: skip
@click.option(
    "--allow-extrapolation", is_flag=True, help="Answer outside the training ranges, flagged."
)
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
def cmd(
    model: Path,
    shape: str,
    skin_type: str,
    stages: tuple[int, ...],
    scheme: str | None,
    allow_extrapolation: bool,
    as_json: bool,
    **numeric: float | None,
) -> None:
    """Predict the maximal-stress quantile of one wound with a model from `woundsweep analyze`.

    MODEL is a model_<split>.json file or a run directory. Prints, per stage, the predicted
    quantile (1 = lowest stresses), the class probabilities and the quantile's stress range
    in kPa (the end classes are bounded by the smallest / largest training stress).
    """
    from ..analysis import load_model, predict
    from ..errors import AnalysisError

    try:
        loaded = load_model(model, scheme)
        quantiles, scheme_name = int(loaded.meta["quantiles"]), str(loaded.meta["scheme"])
    except (AttributeError, TypeError, KeyError, ValueError) as err:  # e.g. metadata `null`
        raise AnalysisError(f"{model}: malformed model metadata ({type(err).__name__})") from None
    params = {
        "wound_shape": shape,
        **{column: numeric[column] for _, column, _, _ in _NUMERIC_PARAMS},
        "skin_type": skin_type,
    }
    preds = predict(loaded, params, list(stages) or None, allow_extrapolation)
    q = quantiles
    if as_json:
        out = {
            "model": str(loaded.path),
            "scheme": scheme_name,
            "quantiles": q,
            "predictions": [p._asdict() for p in preds],
        }
        click.echo(json.dumps(out, indent=1))
        return
    click.echo(f"model: {loaded.path} ({scheme_name} split, {q} quantiles)")
    for p in preds:
        lo, hi = p.stress_range_kPa
        # The end classes are open: their outer edge is only the smallest / largest training value.
        if p.quantile == 1:
            span = f"< {hi:.4g} kPa (training min {lo:.4g})"
        elif p.quantile == q:
            span = f">= {lo:.4g} kPa (training max {hi:.4g})"
        else:
            span = f"{lo:.4g}-{hi:.4g} kPa"
        probs = " ".join(f"{v:.2f}" for v in p.probabilities)
        click.echo(f"stage {p.stage}: quantile {p.quantile}/{q}, {span}, p = [{probs}]")
    if any(p.extrapolated for p in preds):
        flags = sorted({f for p in preds for f in p.extrapolated})
        click.echo("EXTRAPOLATED (outside the training data): " + "; ".join(flags))
