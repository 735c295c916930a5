"""``woundsweep predict [MODEL] --table FILE``: many wounds at once, one a row of a CSV or JSON
file, each checked as one wound's options would be.

Every cell goes through its option's click type (so a row is refused with the text the
option would be refused with), then `require_wound_options`, `parse_params` and
`predict_wound`, as one wound. A refused row does not stop the others: its answer rows carry
the refusal in ``error`` and the command exits 3. A file that cannot be a table (missing,
not UTF-8, not CSV or JSON, an unknown column, no wounds) is one line and exit 2.
"""

from __future__ import annotations

import csv
import io
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from ..core.errors import WoundsweepError, one_line
from .predict import (
    _NUMERIC_PARAMS,
    _warn_if_stale,
    answer_wound,
    parse_params,
    require_wound_options,
    shipped_or_given,
)

if TYPE_CHECKING:
    from ..analysis.model_io import LoadedModel
    from ..analysis.prediction import WoundPrediction

__all__ = ["COLUMNS", "MAX_TABLE_BYTES", "output_columns", "predict_table", "read_table"]

# A table of many thousands of wounds is a few MB.
MAX_TABLE_BYTES = 64 * 2**20


def _alias(flag: str, column: str) -> str | None:
    """The option's name with underscores, where it is not the column's."""
    name = flag.removeprefix("--").replace("-", "_")
    return None if name == column else name


# A table's columns: (name, the option's parameter name, the option's name with underscores
# if it differs, accepted too).
COLUMNS: tuple[tuple[str, str, str | None], ...] = (
    ("wound_shape", "shape", "shape"),
    *((column, column, _alias(flag, column)) for flag, column, _, _ in _NUMERIC_PARAMS),
    ("angle_to_langer_deg", "angle_to_langer", "angle_to_langer"),
    ("skin_type", "skin_type", None),
    ("stage", "stages", None),
)
_NAMES = {n: column for column, _, alias in COLUMNS for n in (column, alias) if n}

# The answer's columns: row, the wound, the stage, then every labelled number of one stage.
_WOUND = [
    "wound_shape", *(column for _, column, _, _ in _NUMERIC_PARAMS), "angle_to_langer_deg",
    "skin_type",
]  # fmt: skip
_WOUND.insert(_WOUND.index("mesh_size_factor") + 1, "mesh_size_factor_default")
_ANSWER_HEAD = [
    "stress_kPa", "interval_low_kPa", "interval_high_kPa", "level", "interval_note", "quantile",
    "stress_range_low_kPa", "stress_range_high_kPa", "estimate_quantile",
]  # fmt: skip
_ANSWER_TAIL = [
    "failure_probability", "failure_note", "orientation_weights", "interpolated",
    "extrapolated", "error",
]  # fmt: skip


def output_columns(quantiles: int) -> list[str]:
    """The answer's columns for a model of ``quantiles`` classes."""
    probs = [f"probability_class_{k}" for k in range(1, quantiles + 1)]
    return ["row", *_WOUND, "stage", *_ANSWER_HEAD, *probs, *_ANSWER_TAIL]


Cells = dict[str, str | None]


def _refuse(path: Path, problem: str) -> WoundsweepError:
    return WoundsweepError(f"--table {path}: {problem}")


def read_table(path: Path) -> list[Cells]:
    """The wounds of a .csv or .json file, one dict a row by column name (`COLUMNS`'
    first names), each cell the text given, stripped (``None``: not given); a one-line
    `WoundsweepError` for a file that cannot be such a table."""
    from ..core.fsutil import read_small_text

    kind = path.suffix.lower()
    if kind not in (".csv", ".json"):
        raise _refuse(path, "expected a .csv or .json file of wounds")
    try:
        text = read_small_text(path, MAX_TABLE_BYTES, f"a {kind[1:].upper()} file")
    except ValueError as err:
        raise _refuse(path, str(err)) from None
    header, rows = _read_csv(path, text) if kind == ".csv" else _read_json(path, text)
    names: dict[str, str] = {}
    for name in header:
        column = _NAMES.get(name)
        if column is None:
            raise _refuse(
                path,
                f"unknown column {name!r} (expected {', '.join(_NAMES)})",
            )
        if column in names.values():
            first = next(k for k, v in names.items() if v == column)
            raise _refuse(path, f"columns {first!r} and {name!r} both give {column}")
        names[name] = column
    if not rows:
        raise _refuse(path, "no wounds (no rows after the header)")
    for need in ("wound_shape", "skin_type", *(c for _, c, req, _ in _NUMERIC_PARAMS if req)):
        if need not in names.values():
            raise _refuse(path, f"no {need} column")
    if not {"orientation_deg", "angle_to_langer_deg"} & set(names.values()):
        raise _refuse(path, "no orientation_deg or angle_to_langer_deg column")
    return [{names[k]: v for k, v in row.items()} for row in rows]


def _cell(value: str | None) -> str | None:
    value = None if value is None else value.strip()
    return value or None


def _read_csv(path: Path, text: str) -> tuple[list[str], list[Cells]]:
    try:
        lines = [r for r in csv.reader(io.StringIO(text, newline="")) if r]
    except csv.Error as err:
        raise _refuse(path, f"not CSV ({err})") from None
    if not lines:
        raise _refuse(path, "empty (expected a header row of column names)")
    header = [h.strip() for h in lines[0]]
    rows = []
    for i, fields in enumerate(lines[1:], start=1):
        if len(fields) != len(header):
            raise _refuse(path, f"row {i} has {len(fields)} fields, the header {len(header)}")
        rows.append({h: _cell(f) for h, f in zip(header, fields)})
    return header, rows


def _json_cell(value: Any) -> str | None:
    """A JSON value as the text an option would be given (null: not given)."""
    if value is None:
        return None
    return _cell(value if isinstance(value, str) else json.dumps(value))


def _read_json(path: Path, text: str) -> tuple[list[str], list[Cells]]:
    try:
        doc = json.loads(text)
    except (ValueError, RecursionError) as err:  # RecursionError: a deeply nested file
        raise _refuse(path, f"not JSON ({str(err) or type(err).__name__})") from None
    if not isinstance(doc, list) or not all(isinstance(r, dict) for r in doc):
        raise _refuse(path, "expected a JSON list of objects, one a wound")
    header = list(dict.fromkeys(k for r in doc for k in r))
    return header, [{k: _json_cell(r.get(k)) for k in header} for r in doc]


class _Row:
    """One wound of the table: its cells as given; as converted by the options' types
    (``shown``: the value, or the text where it does not convert); its stages (``None``: a
    stage cell that is refused); then its answer or the refusal's text."""

    def __init__(self, number: int, cells: Cells, stages: list[int]) -> None:
        self.number, self.cells = number, cells
        self.shown: dict[str, Any] = {c: v for c, v in cells.items() if c != "stage"}
        self.stages: list[int] | None = stages
        self.params: dict[str, Any] = {}
        self.answer: WoundPrediction | None = None
        self.error = ""


def _convert(ctx: click.Context, row: _Row) -> dict[str, Any]:
    """The row's values by parameter name, each through its option's type, in the options'
    order; the first refusal is raised once every cell is tried (``shown`` holds each one
    that converts)."""
    options = {p.name: p for p in ctx.command.get_params(ctx)}
    values: dict[str, Any] = {}
    failed: click.BadParameter | None = None
    for column, name, _ in COLUMNS:
        text = row.cells.get(column)
        if text is None:
            continue
        param = options[name]
        try:
            values[name] = param.type(text, param, ctx)
        except click.BadParameter as err:
            failed = failed or err
            if column == "stage":
                row.stages = None
            continue
        if column == "stage":
            row.stages = [int(values[name])]
        else:
            row.shown[column] = values[name]
    if failed is not None:
        raise failed
    return values


def _answer(
    ctx: click.Context,
    model: Path,
    loaded: LoadedModel,
    row: _Row,
    allow_extrapolation: bool,
    level: float,
) -> None:
    """Answer one row (``row.answer``) or keep its refusal (``row.error``), as one wound's."""
    from .predict import DamagedModel

    try:
        values = _convert(ctx, row)
        require_wound_options(ctx, values)
        numeric = {column: values.get(column) for _, column, _, _ in _NUMERIC_PARAMS}
        angle = values.get("angle_to_langer")
        row.params = parse_params(values["shape"], values["skin_type"], numeric, angle)
        row.answer = answer_wound(
            model, loaded, row.params, row.stages, allow_extrapolation, level, angle is not None
        )
    except click.ClickException as err:
        row.error = one_line(err.format_message())
    except DamagedModel:  # the model's fault, not the row's: no row is answered
        raise
    except WoundsweepError as err:
        row.error = one_line(str(err))


def _text(items: Sequence[str]) -> str:
    return "; ".join(items)


def _records(row: _Row, quantiles: int) -> list[dict[str, Any]]:
    """The row's answer, one record a stage, in `output_columns` order."""
    columns = output_columns(quantiles)
    out: list[dict[str, Any]] = []
    a = row.answer
    if a is None:
        wound = {c: row.shown.get(c) for c in _WOUND}
        stages: list[Any] = row.stages if row.stages is not None else [row.cells.get("stage")]
        for s in stages:
            rec = {"row": row.number, **wound, "stage": s, "error": row.error}
            out.append({c: rec.get(c) for c in columns})
        return out
    p = row.params
    wound = {c: p.get(c) for c in _WOUND}
    wound.update(
        mesh_size_factor=a.mesh_size_factor,
        mesh_size_factor_default=a.mesh_size_default,
        angle_to_langer_deg=90.0 - p["orientation_deg"],
    )
    weights = _text([f"{deg:g}:{w:.6g}" for deg, w in a.orientation_weights])
    for s in a.stages:
        lo, hi = s.interval_kPa or (None, None)
        rec = {
            "row": row.number, **wound, "stage": s.stage, "stress_kPa": s.stress_kPa,
            "interval_low_kPa": lo, "interval_high_kPa": hi, "level": s.level,
            "interval_note": s.interval_note, "quantile": s.quantile,
            "stress_range_low_kPa": s.stress_range_kPa[0],
            "stress_range_high_kPa": s.stress_range_kPa[1],
            "estimate_quantile": s.estimate_quantile,
            **{f"probability_class_{k}": v for k, v in enumerate(s.probabilities, start=1)},
            "failure_probability": a.failure_probability, "failure_note": a.failure_note,
            "orientation_weights": weights, "interpolated": _text(a.interpolated),
            "extrapolated": _text(s.extrapolated), "error": "",
        }  # fmt: skip
        out.append({c: rec.get(c) for c in columns})
    return out


def _csv_value(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    return v


def _format(records: list[dict[str, Any]], columns: list[str], as_json: bool) -> str:
    if as_json:
        return json.dumps(records, indent=1) + "\n"
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for rec in records:
        writer.writerow([_csv_value(rec[c]) for c in columns])
    return buf.getvalue()


def _check_out(out: Path) -> None:
    """A usable --out: .csv or .json, a file that can be written (before any work)."""
    from ..core.fsutil import check_output_file

    if out.suffix.lower() not in (".csv", ".json"):
        raise click.BadParameter(f"{out}: expected a .csv or .json file", param_hint="--out")
    try:
        check_output_file(out)
    except ValueError as err:
        raise WoundsweepError(f"--out {err}") from None


def _refuse_model_target(loaded: LoadedModel, out: Path) -> None:
    """--out neither among the model's files nor in the store of its run directory."""
    from ..analysis.model_io import FAILURE_STEM, SURROGATE_STEM
    from ..analysis.shipped import TRAINED_ON
    from ..analysis.trained_on import model_run_dir
    from ..store.paths import refuse_store_target

    folder = loaded.path.resolve().parent
    stems = (loaded.path.stem, SURROGATE_STEM, FAILURE_STEM)
    files = {folder / f"{s}{x}" for s in stems for x in (".json", "_meta.json")}
    if out.resolve() in files | {folder / TRAINED_ON}:
        raise WoundsweepError(f"--out {out}: one of the model's files (write elsewhere)")
    run_dir = model_run_dir(loaded.path)
    if run_dir is not None:
        refuse_store_target(run_dir, out, "--out")


def _summary(rows: list[_Row]) -> str:
    refused = [r.number for r in rows if r.answer is None]
    line = f"{len(rows) - len(refused)} of {len(rows)} wounds answered"
    if refused:
        shown = ", ".join(str(n) for n in refused[:20])
        more = f" and {len(refused) - 20} more" if len(refused) > 20 else ""
        line += f"; row{'s' if len(refused) > 1 else ''} {shown}{more} refused"
    return line


def predict_table(
    ctx: click.Context,
    model: Path | None,
    table: Path,
    out: Path | None,
    as_json: bool,
    scheme: str | None,
    stages: list[int] | None,
    level: float,
    allow_extrapolation: bool,
) -> None:
    """Answer every wound of ``table`` (`read_table`) with the model (None: the shipped
    models, and a line on stderr of what they were trained on), write the answers (``out``:
    a .csv or .json file by its suffix; else stdout, CSV or ``as_json``), say on stderr how
    many were answered; exit status 3 if a row was refused."""
    from ..analysis import load_model
    from ..analysis.model_io import check_model
    from ..analysis.prediction import check_level
    from ..core.fsutil import atomic_write

    if out is not None:
        _check_out(out)
    check_level(level)
    cells = read_table(table)
    model, record = shipped_or_given(model, scheme)
    loaded = load_model(model, scheme)
    check_model(loaded)  # every field prediction reads, typed: a damaged file is one line
    if out is not None:
        _refuse_model_target(loaded, out)
    _warn_if_stale(loaded)
    if record is not None:
        from ..analysis.shipped import describe

        click.echo(one_line(describe(record)), err=True)
    q = int(loaded.meta["quantiles"])
    default = list(stages) if stages is not None else [int(s) for s in loaded.meta["stages"]]
    rows = [_Row(i, c, default) for i, c in enumerate(cells, start=1)]
    err = sys.stderr
    if len(rows) > 50 and err.isatty():
        with click.progressbar(rows, label="predicting", file=err) as bar:
            for row in bar:
                _answer(ctx, model, loaded, row, allow_extrapolation, level)
    else:
        for row in rows:
            _answer(ctx, model, loaded, row, allow_extrapolation, level)
    records = [rec for row in rows for rec in _records(row, q)]
    fmt_json = as_json if out is None else out.suffix.lower() == ".json"
    text = _format(records, output_columns(q), fmt_json)
    summary = _summary(rows)
    if out is None:
        click.echo(text, nl=False)
    else:
        atomic_write(out, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
        summary += f"; wrote {len(records)} rows to {out}"
    click.echo(one_line(summary), err=True)
    if any(r.answer is None for r in rows):
        raise click.exceptions.Exit(3)
