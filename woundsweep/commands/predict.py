"""``woundsweep predict MODEL_OR_RUN_DIR --shape ... (all parameters)``: one wound's stress
estimate with its interval, the paper's stress quantile and the failure probability.

The orientation is given either as ``--orientation`` (the stiff axis' angle to x, the sweep's
``orientation_deg``) or as ``--angle-to-langer`` (the wound's long axis against the Langer
line, the stiff axis: ``orientation_deg = 90 - angle``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from ..analysis.prediction import MAX_PARAMETER
from ..clitypes import FiniteFloat

if TYPE_CHECKING:
    from ..analysis.model_io import LoadedModel

__all__ = ["cmd", "parse_params"]


# The Table 1 parameters given as numbers: option, manifest column, required, help.
_NUMERIC_PARAMS = (
    ("--dermal-thickness", "dermal_thickness_mm", True, "Epidermis + dermis thickness t_d (mm)."),
    ("--subcutis-thickness-factor", "subcutis_thickness_factor", True, "Subcutis thickness / t_d."),
    ("--patch-size-factor", "patch_size_factor", True, "Patch half-length / total thickness."),
    ("--wound-width-factor", "wound_width_factor", True, "Wound width / patch half-length."),
    (
        "--wound-depth-factor",
        "wound_depth_factor",
        False,
        "Wedge and fusiform: depth / total thickness.",
    ),
    (
        "--wound-aspect-factor",
        "wound_aspect_factor",
        False,
        "Cylindrical only: axis offset / width.",
    ),
    ("--wound-length-factor", "wound_length_factor", False, "Fusiform only: length / width."),
    (
        "--mesh-size-factor",
        "mesh_size_factor",
        False,
        "Mesh size factor (larger = finer) [the finest trained for the shape].",
    ),
    (
        "--orientation",
        "orientation_deg",
        False,
        "Stiff axis angle to x, 0 = across the wound (deg); or --angle-to-langer.",
    ),
)
# The wound's long axis against the Langer line (the stiff axis), 0 = along it.
_ANGLE_HELP = (
    "Angle of the wound's long axis to the Langer line, 0-90 deg (0 = along it): "
    "--orientation 90 - DEG."
)


def _numeric_params(f: Callable[..., None]) -> Callable[..., None]:
    """One float option per `_NUMERIC_PARAMS` entry, in that order, named by its column."""
    for flag, column, required, text in reversed(_NUMERIC_PARAMS):
        kind = FiniteFloat(-MAX_PARAMETER, MAX_PARAMETER)  # float32 in the models: bounded
        f = click.option(flag, column, type=kind, required=required, default=None, help=text)(f)
    return f


def parse_params(
    shape: str,
    skin_type: str,
    numeric: dict[str, float | None],
    angle_to_langer: float | None = None,
) -> dict[str, Any]:
    """The wound's parameters by manifest column name, from the command's options: exactly
    one of ``--orientation`` and ``--angle-to-langer`` (converted to 90 - angle)."""
    params = {
        "wound_shape": shape,
        **{column: numeric[column] for _, column, _, _ in _NUMERIC_PARAMS},
        "skin_type": skin_type,
    }
    if (params["orientation_deg"] is None) == (angle_to_langer is None):
        raise click.UsageError(
            "give the orientation as exactly one of --orientation and --angle-to-langer"
        )
    if angle_to_langer is not None:
        params["orientation_deg"] = 90.0 - angle_to_langer
    return params


def _warn_if_stale(loaded: LoadedModel) -> None:
    """A line on stderr when the model's run has changed its settings since `analyze`."""
    from ..analysis.trained_on import model_run_dir, stale_note
    from ..core.errors import one_line
    from ..core.layout import RunLayout

    run_dir = model_run_dir(loaded.path)
    if run_dir is not None and RunLayout(run_dir).manifest.is_file():
        note = stale_note(run_dir, loaded.meta.get("trained_on"))
        if note:
            click.echo(one_line(f"woundsweep: warning: {note}"), err=True)


def _span(k: int, q: int, lo: float, hi: float) -> str:
    """A quantile class's stress range; the end classes are open (their outer edge is only the
    smallest / largest training value)."""
    if k == 1:
        return f"below {hi:.4g} kPa (training min {lo:.4g})"
    if k == q:
        return f"{lo:.4g} kPa or more (training max {hi:.4g})"
    return f"{lo:.4g}-{hi:.4g} kPa"


def _stage_lines(p: Any, q: int, level: float) -> list[str]:
    """One stage's answer, every number named: the surrogate's p99 of the volume with its
    interval, the classifier's quantile class with its probabilities, and why the two differ
    when they do."""
    lines = [f"stage {p.stage}:"]
    if p.stress_kPa is not None:
        lo, hi = p.interval_kPa or (None, None)
        rng = f"{lo:.4g}-{hi:.4g} kPa" if lo is not None else (p.interval_note or "none")
        lines.append(
            f"  p99 of the volume (stress surrogate): {p.stress_kPa:.4g} kPa; "
            f"{100 * level:g}% interval: {rng}"
        )
    lo, hi = p.stress_range_kPa
    lines.append(
        f"  quantile class (classifier): {p.quantile} of {q}, {_span(p.quantile, q, lo, hi)}, "
        f"probability {p.probabilities[p.quantile - 1]:.2f}"
    )
    probs = " ".join(f"{k + 1}:{v:.2f}" for k, v in enumerate(p.probabilities))
    lines.append(f"  class probabilities (class:probability): {probs}")
    if p.estimate_quantile is not None and p.estimate_quantile != p.quantile:
        lines.append(
            f"  the surrogate's estimate lies in class {p.estimate_quantile}, the classifier's "
            f"most likely class is {p.quantile}: two models trained apart (the classifier on "
            "its split's classes, the surrogate on log stress over the geometry split's "
            "training rows) can disagree; metrics.json and report.md give each one's test "
            "scores"
        )
    return lines


def _basis_lines(basis: dict[str, Any], q: int) -> list[str]:
    """What the answer rests on: training rows and ranges, calibration rows and geometries."""
    ranges = "; ".join(f"{k} {lo:g}..{hi:g}" for k, (lo, hi) in basis["training_ranges"].items())
    lines = [f"trained on: {basis.get('classifier_training_rows') or 'an unrecorded number of'} "
             f"rows (classifier); ranges of the shape: {ranges}"]  # fmt: skip
    if "calibration_rows" in basis:
        geoms = basis.get("calibration_geometries")
        of = f" of {geoms} geometries" if geoms is not None else ""
        by = ", ".join(f"stage {k}: {n}" for k, n in basis["calibration_rows_by_stage"].items())
        lines.append(
            f"interval: split-conformal on {basis['calibration_rows']} calibration rows{of} the "
            f"surrogate never saw ({by}); it holds on average over new geometries inside the "
            "training ranges"
        )
    return lines


@click.command("predict")
@click.argument("model", type=click.Path(path_type=Path))
@click.option(
    "--shape",
    required=True,
    type=click.Choice(["cylindrical", "wedge", "fusiform"]),
    help="Wound shape.",
)
@_numeric_params
@click.option("--angle-to-langer", type=FiniteFloat(0, 90), default=None, help=_ANGLE_HELP)
@click.option("--skin-type", required=True, help="Skin type name, e.g. soft, normal, stiff.")
@click.option(
    "--stage", "stages", type=click.IntRange(1, 6), multiple=True, help="Stage(s) [all trained]."
)
@click.option("--split", "scheme", type=click.Choice(["random", "geometry"]), default=None,
              help="Which model of a run directory [geometry if present].")  # fmt: skip
@click.option(
    "--level", type=FiniteFloat(), default=0.9, show_default=True,
    help="Nominal coverage of the stress interval, between 0 and 1.",
)  # fmt: skip
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
    level: float,
    allow_extrapolation: bool,
    as_json: bool,
    angle_to_langer: float | None,
    **numeric: float | None,
) -> None:
    """Predict one wound's maximal stress with the models from `woundsweep analyze`.

    MODEL is a model_<split>.json file or a run directory. Prints, per stage, the stress
    surrogate's estimate (p99 von Mises, kPa) with its conformal interval at --level, the
    paper's quantile class (1 = lowest stresses), its class probabilities and stress range in
    kPa (the end classes are bounded by the smallest / largest training stress); then the
    probability that the job fails to converge.

    The orientation is --orientation (the stiff axis' angle to x) or --angle-to-langer DEG
    (the wound's long axis against the Langer line; orientation = 90 - DEG). Between two
    trained orientations the models are evaluated at both and their answers weighted
    linearly in the angle. Other values between the trained grid values are answered by the
    trees as they are and flagged as interpolated; values outside the trained ranges are
    refused unless --allow-extrapolation. Without --mesh-size-factor the answer is for the
    finest mesh trained on for the shape (stated).
    """
    from ..analysis import load_model, predict_wound
    from ..analysis.model_io import check_model
    from ..core.errors import AnalysisError

    params = parse_params(shape, skin_type, numeric, angle_to_langer)
    loaded = load_model(model, scheme)
    check_model(loaded)  # every field prediction reads, typed: a damaged file is one line
    q, scheme_name = int(loaded.meta["quantiles"]), str(loaded.meta["scheme"])
    _warn_if_stale(loaded)
    try:
        answer = predict_wound(
            loaded, params, list(stages) or None, allow_extrapolation, level,
            angle_to_langer=angle_to_langer is not None,
        )  # fmt: skip
    except (AttributeError, TypeError, KeyError, ValueError, IndexError) as err:
        # check_model reads what it knows of; a model file damaged past it is still one line.
        raise AnalysisError(f"{model}: damaged model files ({type(err).__name__})") from None
    preds = answer.stages
    if as_json:
        out = {
            "model": str(loaded.path),
            "scheme": scheme_name,
            "quantiles": q,
            "level": level,
            "predictions": [p._asdict() for p in preds],
            "failure_probability": answer.failure_probability,
            "failure_note": answer.failure_note,
            "interpolated": answer.interpolated,
            "orientation_deg": params["orientation_deg"],
            "angle_to_langer_deg": 90.0 - params["orientation_deg"],
            "orientation_weights": [list(p) for p in answer.orientation_weights],
            "mesh_size_factor": answer.mesh_size_factor,
            "mesh_size_factor_default": answer.mesh_size_default,
            "basis": answer.basis,
        }
        click.echo(json.dumps(out, indent=1))
        return
    click.echo(f"model: {loaded.path} ({scheme_name} split, {q} quantiles)")
    for line in _basis_lines(answer.basis, q):
        click.echo(line)
    angle = params["orientation_deg"]
    how = "the finest trained, none given" if answer.mesh_size_default else "given"
    click.echo(
        f"orientation_deg {angle:g} (angle to the Langer line {90 - angle:g} deg); "
        f"mesh_size_factor {answer.mesh_size_factor:g} ({how})"
    )
    for p in preds:
        for line in _stage_lines(p, q, level):
            click.echo(line)
    if answer.failure_probability is None:
        click.echo(f"failure probability: n/a ({answer.failure_note})")
    else:
        click.echo(f"failure probability: {answer.failure_probability:.3f} ({answer.failure_note})")
    if answer.interpolated:
        click.echo(
            "INTERPOLATED (between the trained grid values): " + "; ".join(answer.interpolated)
        )
    if any(p.extrapolated for p in preds):
        flags = sorted({f for p in preds for f in p.extrapolated})
        click.echo("EXTRAPOLATED (outside the training data): " + "; ".join(flags))
