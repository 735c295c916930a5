"""``woundsweep predict MODEL --table FILE``: a table of wounds answered as each would be
alone (the same numbers, the same refusals in the ``error`` column), one row per wound and
stage; CSV and JSON inputs alike; one-line refusals of the file and of conflicting options."""

from __future__ import annotations

import contextlib
import csv
import io
import json
from pathlib import Path

import pandas as pd
import pytest
from synthetic_store import PREDICT_FAST, PREDICT_FLAGS, PREDICT_SWEEP, depth_stress, write_store

from woundsweep.cli import main
from woundsweep.store.reader import read_results

SWEEP, FAST = PREDICT_SWEEP, PREDICT_FAST
NUMBERS = [
    "stress_kPa", "interval_low_kPa", "interval_high_kPa", "level", "quantile",
    "stress_range_low_kPa", "stress_range_high_kPa", "estimate_quantile", "failure_probability",
]  # fmt: skip


@pytest.fixture(scope="module")
def analyzed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rd = tmp_path_factory.mktemp("predict-table") / "run"
    write_store(rd, depth_stress, sweep=SWEEP, seed=3, failed_fraction=0.0)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["analyze", str(rd), "--split", "geometry", *FAST, "--no-figures"]) == 0
    return rd


def _wound(rd: Path, shape: str, k: int = 3) -> dict[str, object]:
    """A converged training row inside every model's trained ranges, as table cells."""
    rows = read_results(rd)
    rows = rows[(rows["wound_shape"] == shape) & (rows["status"] == "converged")]
    for stem in ("model_geometry", "surrogate"):
        meta = json.loads((rd / "analysis" / f"{stem}_meta.json").read_text())
        for col, (lo, hi) in meta["ranges"][shape].items():
            rows = rows[rows[col].between(lo, hi)]
    r = rows.iloc[k]
    own = "wound_depth_factor" if shape == "wedge" else "wound_aspect_factor"
    cols = ["wound_shape", "dermal_thickness_mm", "subcutis_thickness_factor",
            "patch_size_factor", "wound_width_factor", own, "mesh_size_factor",
            "orientation_deg", "skin_type"]  # fmt: skip
    return {c: (r[c] if isinstance(r[c], str) else float(r[c])) for c in cols}


def _argv(wound: dict[str, object]) -> list[str]:
    """The one-wound options of a table row (a None cell: not given)."""
    return [a for c, v in wound.items() if v is not None for a in (PREDICT_FLAGS[c], str(v))]


def _write_csv(path: Path, wounds: list[dict[str, object]]) -> Path:
    columns = list(dict.fromkeys(c for w in wounds for c in w))
    with path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(columns)
        for w in wounds:
            writer.writerow(["" if w.get(c) is None else w[c] for c in columns])
    return path


def _answers(out: str) -> pd.DataFrame:
    return pd.read_csv(
        io.StringIO(out), keep_default_na=False, na_values=[""], float_precision="round_trip"
    )


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_a_one_row_table_gives_the_one_wound_numbers(
    analyzed: Path, tmp_path: Path, run_main
) -> None:
    wound = {**_wound(analyzed, "wedge"), "orientation_deg": 25.0}  # interpolated in angle
    rc, out, err = run_main("predict", analyzed, *_argv(wound), "--json", "--level", "0.8")
    assert rc == 0, err
    one = json.loads(out)
    table = _write_csv(tmp_path / "t.csv", [wound])
    rc, out, err = run_main("predict", analyzed, "--table", table, "--level", "0.8", "--json")
    assert rc == 0, err
    assert _one_line(err) == "1 of 1 wounds answered"
    rows = json.loads(out)
    assert (
        [r["stage"] for r in rows] == [p["stage"] for p in one["predictions"]] == [1, 2, 3, 4, 5, 6]
    )
    q = one["quantiles"]
    for r, p in zip(rows, one["predictions"]):
        assert r["row"] == 1 and r["error"] == ""
        lo, hi = p["interval_kPa"]
        expect = {
            "stress_kPa": p["stress_kPa"], "interval_low_kPa": lo, "interval_high_kPa": hi,
            "level": 0.8, "quantile": p["quantile"], "estimate_quantile": p["estimate_quantile"],
            "stress_range_low_kPa": p["stress_range_kPa"][0],
            "stress_range_high_kPa": p["stress_range_kPa"][1],
            "failure_probability": one["failure_probability"],
        }  # fmt: skip
        assert {k: r[k] for k in NUMBERS} == expect
        assert [r[f"probability_class_{k}"] for k in range(1, q + 1)] == p["probabilities"]
        assert f"probability_class_{q + 1}" not in r
        assert r["interval_note"] == p["interval_note"] and r["extrapolated"] == ""
        assert r["failure_note"] == one["failure_note"]
        assert r["interpolated"] == "; ".join(one["interpolated"]) != ""
        assert r["orientation_weights"] == "; ".join(
            f"{a:g}:{w:.6g}" for a, w in one["orientation_weights"]
        )
        assert r["orientation_deg"] == 25.0 and r["angle_to_langer_deg"] == 65.0
        assert r["mesh_size_factor"] == one["mesh_size_factor"]
        assert r["mesh_size_factor_default"] is False
        assert r["wound_aspect_factor"] is None and r["wound_length_factor"] is None
    # The CSV on stdout holds the same numbers (full precision).
    rc, out, _ = run_main("predict", analyzed, "--table", table, "--level", "0.8")
    assert rc == 0
    frame = _answers(out)
    for r, (_, c) in zip(rows, frame.iterrows()):
        assert all(c[k] == r[k] if r[k] is not None else pd.isna(c[k]) for k in NUMBERS)


def test_rows_times_stages_and_a_rows_own_stage(analyzed: Path, tmp_path: Path, run_main) -> None:
    wounds = [_wound(analyzed, "wedge", 0), _wound(analyzed, "cylindrical", 1),
              _wound(analyzed, "wedge", 5)]  # fmt: skip
    table = _write_csv(tmp_path / "t.csv", wounds)
    rc, out, err = run_main("predict", analyzed, "--table", table)
    assert rc == 0, err
    frame = _answers(out)
    assert len(frame) == 3 * 6 and list(frame["row"]) == [r for r in (1, 2, 3) for _ in range(6)]
    rc, out, err = run_main("predict", analyzed, "--table", table, "--stage", "2", "--stage", "5")
    frame = _answers(out)
    assert rc == 0 and len(frame) == 3 * 2 and list(frame["stage"]) == [2, 5] * 3
    # A stage column overrides --stage for its rows; an empty cell keeps it.
    staged = _write_csv(
        tmp_path / "s.csv", [{**wounds[0], "stage": 4}, {**wounds[1], "stage": None}]
    )
    rc, out, err = run_main("predict", analyzed, "--table", staged, "--stage", "2", "--stage", "5")
    frame = _answers(out)
    assert rc == 0 and list(zip(frame["row"], frame["stage"])) == [(1, 4), (2, 2), (2, 5)]


def test_a_refused_row_carries_the_one_wound_refusal(
    analyzed: Path, tmp_path: Path, run_main
) -> None:
    good = _wound(analyzed, "wedge")
    bad = [
        {**good, "dermal_thickness_mm": 3.0},  # outside the training data
        {**good, "wound_width_factor": "x"},  # not a number
        {**good, "wound_aspect_factor": 0.1},  # the other shape's factor
        {**good, "wound_width_factor": None, "skin_type": None},  # required, missing
        {**good, "angle_to_langer_deg": 30.0},  # and an orientation
        {**good, "stage": 7},
    ]
    wounds = [good, *bad, good]
    table = _write_csv(tmp_path / "t.csv", wounds)
    rc, out, err = run_main("predict", analyzed, "--table", table, "--stage", "1", "--stage", "3")
    assert rc == 3
    assert _one_line(err) == "2 of 8 wounds answered; rows 2, 3, 4, 5, 6, 7 refused"
    frame = _answers(out)
    # One row per stage for every wound; one for the refused stage cell (no stages to give).
    assert list(frame["row"]) == [1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 8, 8]
    for n, wound in enumerate(bad, start=2):
        rc1, out1, err1 = run_main(
            "predict", analyzed, *_argv(wound), "--stage", "1", "--stage", "3"
        )
        assert rc1 == 2 and out1 == ""
        errors = set(frame.loc[frame["row"] == n, "error"])
        assert errors == {_one_line(err1).removeprefix("woundsweep: error: ")}
        assert frame.loc[frame["row"] == n, "stress_kPa"].isna().all()
    assert (
        frame.loc[frame["row"] == 8, "stress_kPa"].tolist()
        == frame.loc[frame["row"] == 1, "stress_kPa"].tolist()
    )
    assert frame.loc[frame["row"].isin([1, 8]), "error"].isna().all()
    shown = frame[frame["row"] == 3].iloc[0]
    assert shown["wound_width_factor"] == "x" and float(shown["dermal_thickness_mm"]) == 1.0
    assert frame.loc[frame["row"] == 7, "stage"].tolist() == [7]
    assert "Invalid value for '--wound-width-factor'" in shown["error"]
    # With --allow-extrapolation the thicker wound is answered, flagged, without an interval.
    rc, out, _ = run_main("predict", analyzed, "--table", table, "--allow-extrapolation")
    row2 = _answers(out).query("row == 2")
    assert rc == 3 and row2["error"].isna().all() and row2["interval_low_kPa"].isna().all()
    assert row2["extrapolated"].str.contains("dermal_thickness_mm=3").all()


def test_csv_and_json_tables_agree_and_angle_to_langer_is_90_minus_orientation(
    analyzed: Path, tmp_path: Path, run_main
) -> None:
    wounds = [_wound(analyzed, "wedge", 0), _wound(analyzed, "cylindrical", 2)]
    wounds[1]["orientation_deg"] = 30.0
    by_orientation = _write_csv(tmp_path / "o.csv", wounds)
    by_angle = [{**{k: v for k, v in w.items() if k != "orientation_deg"},
                 "angle_to_langer_deg": 90.0 - w["orientation_deg"]} for w in wounds]  # fmt: skip
    as_json = tmp_path / "a.json"
    as_json.write_text(json.dumps(by_angle))
    as_csv = _write_csv(tmp_path / "a.csv", by_angle)
    # The options' names are accepted as the columns' too.
    aliased = tmp_path / "alias.json"
    aliased.write_text(json.dumps([
        {("shape" if k == "wound_shape" else "angle_to_langer" if k == "angle_to_langer_deg"
          else "dermal_thickness" if k == "dermal_thickness_mm" else k): v for k, v in w.items()}
        for w in by_angle
    ]))  # fmt: skip
    outs = {}
    for name, table in [("o", by_orientation), ("j", as_json), ("c", as_csv), ("al", aliased)]:
        rc, outs[name], err = run_main("predict", analyzed, "--table", table, "--stage", "2")
        assert rc == 0, err
    assert outs["j"] == outs["c"] == outs["al"]
    o, a = _answers(outs["o"]), _answers(outs["j"])
    numbers = [c for c in o.columns if c in NUMBERS or c.startswith("probability_class_")]
    pd.testing.assert_frame_equal(o[numbers], a[numbers])
    assert list(a["orientation_deg"]) == [w["orientation_deg"] for w in wounds]
    assert list(a["angle_to_langer_deg"]) == [90.0 - w["orientation_deg"] for w in wounds]
    # --out by suffix: the same records as CSV and as JSON.
    for suffix in ("csv", "json"):
        rc, out, err = run_main(
            "predict",
            analyzed,
            "--table",
            as_csv,
            "--stage",
            "2",
            "--out",
            tmp_path / f"r.{suffix}",
        )
        assert (
            rc == 0
            and out == ""
            and _one_line(err).endswith(f"wrote 2 rows to {tmp_path}/r.{suffix}")
        )
    written = _answers((tmp_path / "r.csv").read_text())
    pd.testing.assert_frame_equal(written, a)
    records = json.loads((tmp_path / "r.json").read_text())
    assert [list(r) for r in records] == [list(a.columns)] * 2
    assert [r["stress_kPa"] for r in records] == list(a["stress_kPa"])


@pytest.mark.parametrize(
    "name, content, needle",
    [
        ("t.csv", None, "cannot read file"),
        ("t.csv", "", "empty"),
        ("t.txt", "wound_shape\nwedge\n", "expected a .csv or .json file"),
        ("t.csv", "COLS\n", "no wounds"),
        ("t.csv", "COLS,colour\n", "unknown column 'colour'"),
        ("t.csv", "COLS,shape\n", "columns 'wound_shape' and 'shape' both give wound_shape"),
        ("t.csv", "COLS\nwedge,1\n", "row 1 has 2 fields"),
        ("t.json", "{}", "expected a JSON list of objects"),
        ("t.json", "[{", "not JSON"),
        ("t.json", "[]", "no wounds"),
        ("t.json", '[{"dermal_thickness_mm": 1}]', "no wound_shape column"),
        ("t.csv", "\0\0", "binary data"),
    ],
    ids=["missing", "empty", "not-csv-or-json", "header-only", "unknown-column", "alias-twice",
         "ragged", "json-object", "json-broken", "json-empty", "no-required-column", "binary"],
)  # fmt: skip
def test_a_file_that_is_no_table_is_one_line(
    analyzed: Path, tmp_path: Path, run_main, name: str, content: str | None, needle: str
) -> None:
    cols = "wound_shape,dermal_thickness_mm,subcutis_thickness_factor,patch_size_factor," \
           "wound_width_factor,orientation_deg,skin_type"  # fmt: skip
    path = tmp_path / name
    if content is not None:
        path.write_text(content.replace("COLS", cols))
    rc, out, err = run_main("predict", analyzed, "--table", path)
    line = _one_line(err)
    assert rc == 2 and out == "" and line.startswith("woundsweep: error: --table ")
    assert needle in line, line


def test_conflicting_options_and_outputs_are_one_line(
    analyzed: Path, tmp_path: Path, run_main
) -> None:
    wound = _wound(analyzed, "wedge")
    table = _write_csv(tmp_path / "t.csv", [wound])
    rc, _, err = run_main(
        "predict", analyzed, "--table", table, "--shape", "wedge", "--orientation", "0"
    )
    assert rc == 2 and _one_line(err) == (
        "woundsweep: error: --table gives each wound's parameters: drop --shape, --orientation"
    )
    rc, _, err = run_main("predict", analyzed, *_argv(wound), "--out", tmp_path / "x.csv")
    assert rc == 2 and "--out needs --table" in _one_line(err)
    rc, _, err = run_main(
        "predict", analyzed, "--table", table, "--json", "--out", tmp_path / "x.csv"
    )
    assert rc == 2 and "--out's suffix picks its format" in _one_line(err)
    assert not (tmp_path / "x.csv").exists()
    rc, _, err = run_main("predict", analyzed, "--table", table, "--out", tmp_path / "x.txt")
    assert rc == 2 and "expected a .csv or .json file" in _one_line(err)
    model = analyzed / "analysis" / "model_geometry_meta.json"
    before = model.read_bytes()
    rc, _, err = run_main("predict", analyzed, "--table", table, "--out", model)
    assert rc == 2 and "one of the model's files" in _one_line(err)
    assert model.read_bytes() == before
    rc, _, err = run_main("predict", analyzed, "--table", table, "--level", "1.5")
    assert rc == 2 and "interval level 1.5" in _one_line(err)
    # Without --table the wound's required options are still all named at once.
    rc, _, err = run_main("predict", analyzed, "--shape", "wedge")
    assert rc == 2 and _one_line(err) == (
        "woundsweep: error: predict: missing --dermal-thickness, --subcutis-thickness-factor, "
        "--patch-size-factor, --wound-width-factor, --skin-type (see --help)"
    )
    rc, _, err = run_main("predict", analyzed, *_argv({**wound, "skin_type": None}))
    assert rc == 2 and "Missing option '--skin-type'" in _one_line(err)
