"""The CLI's shared contract beyond the bad-input table: every missing required option in one
message, the element of the stored rows named by `status`, and the analysis figures' log axes
labelled with plain numbers that do not overlap."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from woundsweep.cli import main


def test_all_missing_options_in_one_line(capsys) -> None:
    assert main(["view"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["woundsweep: error: view: missing RUN_DIR, --out (see --help)"]
    # One missing option keeps click's own message.
    assert main(["view", "somewhere"]) == 2
    assert "Missing option '--out'" in capsys.readouterr().err
    # Help still wins over missing options.
    assert main(["view", "--help"]) == 0
    assert "Usage:" in capsys.readouterr().out


def test_status_names_the_element_of_the_stored_rows(empty_run: Path, capsys) -> None:
    from store_files import store_converged

    assert main(["status", str(empty_run), "--json"]) == 0
    out, err = capsys.readouterr()
    data = json.loads(out)
    assert data["element_degree"] is None and data["element"] is None  # nothing stored
    # The time it took: in the document with --json (stderr stays silent), else on stderr.
    assert err == "" and data["read_time_s"] >= 0
    assert main(["status", str(empty_run)]) == 0
    out, err = capsys.readouterr()
    assert out.splitlines()[0] == "sweep demo: element n/a (no stored results)"
    assert re.fullmatch(r"status: 32 jobs \(0 stored\) read in \d+\.\d s\n", err), err
    store_converged(empty_run, 0)
    assert main(["status", str(empty_run)]) == 0
    assert (
        capsys.readouterr().out.splitlines()[0] == "sweep demo: element P2 (quadratic tetrahedra)"
    )
    assert main(["status", str(empty_run), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["element_degree"] == 2 and data["element"].startswith("P2")


def _labels(fig):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    r = canvas.get_renderer()
    out = []
    for ax in fig.axes:
        for axis, i in ((ax.xaxis, 0), (ax.yaxis, 1)):
            lo, hi = sorted(axis.get_view_interval())
            labs = [
                t for t in axis.get_ticklabels(which="both")
                if t.get_visible() and t.get_text() and lo <= t.get_position()[i] <= hi
            ]  # fmt: skip
            out.append(([t.get_text() for t in labs], [t.get_window_extent(r) for t in labs]))
    return out


@pytest.mark.parametrize("lo, hi", [(5.5, 9.0), (4.0, 50.0), (4.0, 60.0), (3.0, 400.0), (1.0, 5e4)])
def test_log_axes_plain_numbers_no_overlap(lo: float, hi: float) -> None:
    from woundsweep.analysis.figures import stiff_vs_soft

    rng = np.random.default_rng(0)
    soft = np.geomspace(lo, hi, 60)
    pairs = pd.DataFrame(
        {"wound_shape": ["wedge", "cylindrical"] * 30, "soft_kPa": soft,
         "stiff_kPa": soft * rng.uniform(0.95, 1.05, 60)}
    )  # fmt: skip
    stat = {"sign_test_p": 0.1, "fraction_stiff_greater": 0.5, "stiff_greater": 15, "pairs": 30}
    fig = stiff_vs_soft(pairs, {"wedge": stat, "cylindrical": stat})
    for texts, boxes in _labels(fig):
        assert len(texts) >= 2, texts
        assert all(re.fullmatch(r"\d+(\.\d+)?", t) for t in texts), texts  # no 6x10^0
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                assert not boxes[i].overlaps(boxes[j]), (texts[i], texts[j])


_THREADS = """
import json, sys
from woundsweep.cli import cli
cli.get_command(None, sys.argv[1])
import numpy, threadpoolctl
print(json.dumps([i["num_threads"] for i in threadpoolctl.threadpool_info()
                  if i["user_api"] == "blas"]))
"""


@pytest.mark.parametrize("command", ["solve", "converge", "case", "run"])
def test_solving_commands_load_a_serial_blas(command: str) -> None:
    """The thread count is fixed when numpy loads: the solving commands set it first (a
    threaded OpenBLAS costs seconds on the solver's batched 3 x 3 inverses on busy cores)."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run(
        [sys.executable, "-c", _THREADS, command],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert json.loads(out) == [1]


def test_other_commands_keep_the_blas_threads(monkeypatch) -> None:
    from woundsweep.cli import cli

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    cli.get_command(None, "generate")
    assert "OPENBLAS_NUM_THREADS" not in __import__("os").environ
