"""Bad inputs through the real CLI: exit status, one line, no traceback, no hang.

Each case runs `woundsweep.cli.main` in a fresh process forked from a server that imported the
CLI once (tests/support/cli_forkserver.py), with a timeout; a few also run through `python -m
woundsweep` to show that the two agree. For every refused input the case asserts the exit
status, exactly one line on stderr naming the problem (and no traceback), and that the run
directory (or the directory it would have created) is unchanged byte for byte. None of these
need DOLFINx. The cases are listed in tests/support/bad_input_cases.py and (fuzz round 4:
unbounded sizes, outputs aimed at the store, unknown options first)
tests/support/bad_input_cases_round4.py; damaged and stale files in a run directory are the
subject of test_store_damage.py, links, named pipes, stale viewers' inputs and the
environment of test_fuzz_round4.py.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from bad_input_cases import CASES as ROUNDS_1_3
from bad_input_cases import Case
from bad_input_cases_round4 import ROUND4_CASES
from cli_run import WS, ForkCli
from dir_snapshot import snapshot

CASES = ROUNDS_1_3 + ROUND4_CASES


def test_at_least_150_distinct_cases() -> None:
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids)) and len(ids) >= 150, len(ids)
    print(f"{len(ids)} bad inputs")


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_one_line(case: Case, cli: ForkCli, demo_run: Path, tmp_path: Path) -> None:
    ws = tmp_path
    shutil.copytree(demo_run, ws / "run")
    argv = case.setup(ws)
    watched = ws / case.watch
    before = snapshot(watched)
    res = cli(argv, ws, fsize=case.fsize, timeout=30)
    assert not res.timed_out, f"hung: {argv}"
    assert "Traceback" not in res.stderr, res.stderr
    lines = res.stderr.splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("woundsweep: error: "), lines[0]
    assert res.code == case.code, (res.code, res.stderr)
    assert case.contains in lines[0]
    assert snapshot(watched) == before, "the refused input changed the directory"
    if case.watch == "new":
        assert not watched.exists()


SUBPROCESS_SAMPLE = [
    "file-fifo",
    "run--timeout-0",
    "rule-0",
    "gen-out-under-file",
    "predict-meta-0",
]


@pytest.mark.parametrize("case_id", SUBPROCESS_SAMPLE)
def test_python_m_woundsweep_agrees(
    case_id: str, cli: ForkCli, demo_run: Path, tmp_path: Path
) -> None:
    """The fork server gives what `python -m woundsweep` gives (same status and line)."""
    case = next(c for c in CASES if c.id == case_id)
    shutil.copytree(demo_run, tmp_path / "run")
    argv = case.setup(tmp_path)
    forked = cli(argv, tmp_path)
    real = subprocess.run(
        [*WS, *argv], cwd=tmp_path, capture_output=True, text=True, timeout=60,
        stdin=subprocess.DEVNULL,
    )  # fmt: skip
    assert (real.returncode, real.stderr) == (forked.code, forked.stderr)
