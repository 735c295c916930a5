"""``woundsweep predict MODEL_OR_RUN_DIR --shape ... (all parameters)``: one wound's stress quantile."""

from __future__ import annotations

import json
from pathlib import Path

import click

__all__ = ["cmd"]


@click.command("predict")
@click.argument("model", type=click.Path(path_type=Path))
@click.option(
    "--shape", required=True, type=click.Choice(["cylindrical", "wedge"]), help="Wound shape."
)
@click.option(
    "--dermal-thickness", required=True, type=float, help="Epidermis + dermis thickness t_d (mm)."
)
@click.option(
    "--subcutis-thickness-factor", required=True, type=float, help="Subcutis thickness / t_d."
)
@click.option(
    "--patch-size-factor", required=True, type=float, help="Patch half-length / total thickness."
)
@click.option(
    "--wound-width-factor", required=True, type=float, help="Wound width / patch half-length."
)
@click.option(
    "--wound-depth-factor", type=float, default=None, help="Wedge only: depth / total thickness."
)
@click.option(
    "--wound-aspect-factor", type=float, default=None, help="Cylindrical only: axis offset / width."
)
@click.option(
    "--mesh-size-factor", required=True, type=float, help="Mesh size factor (larger = finer)."
)
@click.option(
    "--orientation", required=True, type=float, help="Wound axis vs stiff material axis (deg)."
)
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
    dermal_thickness: float,
    subcutis_thickness_factor: float,
    patch_size_factor: float,
    wound_width_factor: float,
    wound_depth_factor: float | None,
    wound_aspect_factor: float | None,
    mesh_size_factor: float,
    orientation: float,
    skin_type: str,
    stages: tuple[int, ...],
    scheme: str | None,
    allow_extrapolation: bool,
    as_json: bool,
) -> None:
    """Predict the maximal-stress quantile of one wound with a model from `woundsweep analyze`.

    MODEL is a model_<split>.json file or a run directory. Prints, per stage, the predicted
    quantile (1 = lowest stresses), the class probabilities and the quantile's stress range
    in kPa (the end classes are bounded by the smallest / largest training stress).
    """
    from ..analysis import load_model, predict

    loaded = load_model(model, scheme)
    params = {
        "wound_shape": shape,
        "dermal_thickness_mm": dermal_thickness,
        "subcutis_thickness_factor": subcutis_thickness_factor,
        "patch_size_factor": patch_size_factor,
        "wound_width_factor": wound_width_factor,
        "wound_depth_factor": wound_depth_factor,
        "wound_aspect_factor": wound_aspect_factor,
        "mesh_size_factor": mesh_size_factor,
        "orientation_deg": orientation,
        "skin_type": skin_type,
    }
    preds = predict(loaded, params, list(stages) or None, allow_extrapolation)
    q = loaded.meta["quantiles"]
    if as_json:
        out = {
            "model": str(loaded.path),
            "scheme": loaded.meta["scheme"],
            "quantiles": q,
            "predictions": [p._asdict() for p in preds],
        }
        click.echo(json.dumps(out, indent=1))
        return
    click.echo(f"model: {loaded.path} ({loaded.meta['scheme']} split, {q} quantiles)")
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
