"""``woundsweep predict [MODEL_OR_RUN_DIR] --shape ... (all parameters)``: one wound's stress
estimate with its interval, the paper's stress quantile and the failure probability.

Without a model, the models shipped with woundsweep answer (`analysis.shipped`), and the
output says what they were trained on.

The orientation is given either as ``--orientation`` (the stiff axis' angle to x, the sweep's
``orientation_deg``) or as ``--angle-to-langer`` (the wound's long axis against the Langer
line, the stiff axis: ``orientation_deg = 90 - angle``).

``--table FILE`` answers a table of wounds instead (`predict_table`): each row is read through
the same options' types, `require_wound_options` and `parse_params` as one wound."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from ..analysis.prediction import MAX_PARAMETER
from ..clitypes import FiniteFloat
from ..core.errors import AnalysisError

if TYPE_CHECKING:
    from ..analysis.model_io import LoadedModel
    from ..analysis.prediction import WoundPrediction

__all__ = [
    "REQUIRED_WITHOUT_TABLE",
    "DamagedModel",
    "answer_wound",
    "cmd",
    "parse_params",
    "require_wound_options",
    "shipped_or_given",
]


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


# Required for one wound, not given with --table (so not click's `required`: the command
# checks them, `require_wound_options`), by parameter name.
REQUIRED_WITHOUT_TABLE = frozenset(
    {"shape", "skin_type", *(column for _, column, required, _ in _NUMERIC_PARAMS if required)}
)
_REQUIRED_NOTE = " [required without --table]"


def _numeric_params(f: Callable[..., None]) -> Callable[..., None]:
    """One float option per `_NUMERIC_PARAMS` entry, in that order, named by its column."""
    for flag, column, required, text in reversed(_NUMERIC_PARAMS):
        kind = FiniteFloat(-MAX_PARAMETER, MAX_PARAMETER)  # float32 in the models: bounded
        text += _REQUIRED_NOTE if required else ""
        f = click.option(flag, column, type=kind, default=None, help=text)(f)
    return f


def require_wound_options(ctx: click.Context, given: Iterable[str]) -> None:
    """Refuse a wound without every required option (``given``: the parameter names given):
    click's message for one, every one named in one line for more (as `cli.missing_required`)."""
    have = set(given)
    missing = [
        p for p in ctx.command.get_params(ctx)
        if p.name in REQUIRED_WITHOUT_TABLE and p.name not in have
    ]  # fmt: skip
    if len(missing) == 1:
        raise click.MissingParameter(ctx=ctx, param=missing[0])
    if missing:
        names = ", ".join(max(p.opts, key=len) for p in missing)
        raise click.UsageError(f"{ctx.info_name}: missing {names} (see --help)", ctx)


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


class DamagedModel(AnalysisError):
    """Model files that `check_model` passed and prediction could not read."""


def answer_wound(
    model: Path,
    loaded: LoadedModel,
    params: dict[str, Any],
    stages: Sequence[int] | None,
    allow_extrapolation: bool,
    level: float,
    angle_to_langer: bool,
) -> WoundPrediction:
    """`predict_wound`, with a model file damaged past `check_model` reported in one line
    (`DamagedModel`)."""
    from ..analysis import predict_wound

    try:
        return predict_wound(
            loaded, params, stages, allow_extrapolation, level, angle_to_langer=angle_to_langer
        )
    except (AttributeError, TypeError, KeyError, ValueError, IndexError) as err:
        # check_model reads what it knows of; a model file damaged past it is still one line.
        raise DamagedModel(f"{model}: damaged model files ({type(err).__name__})") from None


def _shipped_doc(record: dict[str, Any]) -> dict[str, Any]:
    """--json's account of the shipped models: the line, then their record."""
    from ..analysis.shipped import describe

    return {"description": describe(record), "trained_on": record}


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
        if basis.get("calibration"):
            lines.append(
                f"stress surrogate: {basis.get('surrogate', 'trees')}; calibration: "
                f"{basis['calibration']}"
            )
    return lines


def shipped_or_given(model: Path | None, scheme: str | None) -> tuple[Path, dict[str, Any] | None]:
    """``model``, or the shipped models' directory and their record when it is None."""
    if model is not None:
        return model, None
    from ..analysis import shipped

    return shipped.shipped_model(scheme)


@click.command("predict")
@click.argument("model", type=click.Path(path_type=Path), required=False)
@click.option(
    "--shape",
    type=click.Choice(["cylindrical", "wedge", "fusiform"]),
    help="Wound shape." + _REQUIRED_NOTE,
)
@_numeric_params
@click.option("--angle-to-langer", type=FiniteFloat(0, 90), default=None, help=_ANGLE_HELP)
@click.option("--skin-type", help="Skin type name, e.g. soft, normal, stiff." + _REQUIRED_NOTE)
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
@click.option(
    "--table", type=click.Path(path_type=Path), default=None,
    help="A .csv or .json file of wounds, one a row (columns: see below), in place of the "
    "wound's options.",
)  # fmt: skip
@click.option(
    "--out", type=click.Path(path_type=Path), default=None,
    help="With --table: write the answers to this .csv or .json file [stdout].",
)  # fmt: skip
def cmd(
    model: Path | None,
    shape: str | None,
    skin_type: str | None,
    stages: tuple[int, ...],
    scheme: str | None,
    level: float,
    allow_extrapolation: bool,
    as_json: bool,
    table: Path | None,
    out: Path | None,
    angle_to_langer: float | None,
    **numeric: float | None,
) -> None:
    """Predict a wound's (or a table of wounds') maximal stress with the models from
    `woundsweep analyze`.

    MODEL is a model_<split>.json file or a run directory. Without it the models shipped
    with woundsweep answer (`make models` builds them from the charted tables), and the
    output says what they were trained on (a line after the model's, on stderr with
    --table; "shipped_model" with --json). Prints, per stage, the stress
    surrogate's estimate (p99 von Mises, kPa) with its conformal interval at --level, the
    paper's quantile class (1 = lowest stresses), its class probabilities and stress range in
    kPa (the end classes are bounded by the smallest / largest training stress); then the
    probability that the job fails to converge.

    The orientation is --orientation (the stiff axis' angle to x) or --angle-to-langer DEG
    (the wound's long axis against the Langer line; orientation = 90 - DEG). Between two
    trained orientations the models are evaluated at both and their answers weighted
    linearly in cos(2 x orientation), of which every result is a function by symmetry (a
    Gaussian-process surrogate, `analyze --param surrogate=gp`, is
    evaluated at the angle itself). Other values between the trained grid values are
    answered by the models as they are and flagged as interpolated; values outside the trained ranges are
    refused unless --allow-extrapolation. Without --mesh-size-factor the answer is for the
    finest mesh trained on for the shape (stated).

    --table FILE answers a table of wounds instead, none of the wound's options given
    (--level, --split, --stage and --allow-extrapolation apply to every row): a .csv file
    (a header row of column names, then one wound a row; blank lines skipped) or a .json
    file (a list of objects, one a wound). An empty cell, a JSON null or an absent key is an
    option not given. The columns (the option's name with underscores is accepted too where
    shown in brackets); the required options' columns and one of the orientation's must be
    there, any other is refused:

    \b
      wound_shape (shape)                       --shape
      dermal_thickness_mm (dermal_thickness)    --dermal-thickness
      subcutis_thickness_factor                 --subcutis-thickness-factor
      patch_size_factor                         --patch-size-factor
      wound_width_factor                        --wound-width-factor
      wound_depth_factor                        --wound-depth-factor
      wound_aspect_factor                       --wound-aspect-factor
      wound_length_factor                       --wound-length-factor
      mesh_size_factor                          --mesh-size-factor
      orientation_deg (orientation)             --orientation
      angle_to_langer_deg (angle_to_langer)     --angle-to-langer
      skin_type                                 --skin-type
      stage                                     one stage, in place of --stage

    Each row is checked as its options would be, and a refused row does not stop the
    others. The answer has one row per wound and stage, CSV on stdout (with --json, a JSON
    list of objects) or in --out FILE (.csv or .json by the suffix, written atomically):
    row (the wound's 1-based place among the table's rows), the wound's parameters
    (orientation_deg and angle_to_langer_deg both; mesh_size_factor the one answered for,
    mesh_size_factor_default), stage, stress_kPa, interval_low_kPa, interval_high_kPa,
    level, interval_note, quantile, stress_range_low_kPa, stress_range_high_kPa,
    estimate_quantile, probability_class_1 ... probability_class_Q, failure_probability,
    failure_note, orientation_weights (DEG:WEIGHT; ...), interpolated, extrapolated (flags
    joined by "; ") and error: a refused row's refusal, worded as the one wound's (its
    other answer columns empty, its cells as given). stderr ends with "N of M wounds
    answered" (and the refused rows); the exit status is 0 if every row was answered, 3 if
    a row was refused, 2 for a file that is no such table.
    """
    from ..analysis import load_model
    from ..analysis.model_io import check_model

    ctx = click.get_current_context()
    wound = {"shape": shape, "skin_type": skin_type, "angle_to_langer": angle_to_langer}
    given = [k for k, v in {**wound, **numeric}.items() if v is not None]
    if table is not None:
        from .predict_table import predict_table

        conflict = [max(p.opts, key=len) for p in ctx.command.get_params(ctx) if p.name in given]
        if conflict:
            raise click.UsageError(
                f"--table gives each wound's parameters: drop {', '.join(conflict)}"
            )
        if as_json and out is not None and out.suffix.lower() != ".json":
            raise click.UsageError(f"--json and --out {out}: --out's suffix picks its format")
        predict_table(
            ctx, model, table, out, as_json, scheme, list(stages) or None, level,
            allow_extrapolation,
        )  # fmt: skip
        return
    if out is not None:
        raise click.UsageError("--out needs --table (one wound's answer is printed)")
    require_wound_options(ctx, given)
    assert shape is not None and skin_type is not None  # require_wound_options
    params = parse_params(shape, skin_type, numeric, angle_to_langer)
    model, record = shipped_or_given(model, scheme)
    loaded = load_model(model, scheme)
    check_model(loaded)  # every field prediction reads, typed: a damaged file is one line
    q, scheme_name = int(loaded.meta["quantiles"]), str(loaded.meta["scheme"])
    _warn_if_stale(loaded)
    answer = answer_wound(
        model, loaded, params, list(stages) or None, allow_extrapolation, level,
        angle_to_langer is not None,
    )  # fmt: skip
    preds = answer.stages
    if as_json:
        doc = {
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
            "shipped_model": None if record is None else _shipped_doc(record),
        }
        click.echo(json.dumps(doc, indent=1))
        return
    click.echo(f"model: {loaded.path} ({scheme_name} split, {q} quantiles)")
    if record is not None:
        from ..analysis.shipped import describe

        click.echo(describe(record))
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
