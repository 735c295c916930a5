"""Bad inputs of fuzz round 4 for tests/commands/test_bad_inputs.py (the `Case` format of
bad_input_cases.py): unbounded counts and sizes (shard counts, a clinical case's lengths and
sutures, refined meshes, a fusiform wound far below its patch's scale), outputs aimed at the
store, a damaged SLURM record before a submission, and unknown options placed before the
required ones. Each class is generated over its members; the cases that need stored
results, links, named pipes or the environment are in tests/commands/test_fuzz_round4.py."""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path

import yaml
from bad_input_cases import Case, _in_run, _write
from cli_run import demo_doc


def _case(*argv: str) -> Callable[[Path], list[str]]:
    def setup(ws: Path) -> list[str]:
        return ["case", "--out", "case-report", *argv]

    return setup


# A clinical case's lengths and sutures far outside any wound (each refused before any
# suture position is built or anything is meshed).
_CASE_UNBOUNDED = {
    "--length-mm": ("1e6", "1e300", "1e-300", "5e-324", "1001", "0.001"),
    "--width-mm": ("1e-300", "5e-324"),
    "--dermis-mm": ("1e-300", "1e6"),
    "--subcutis-mm": ("1e-300", "1e6"),
    "--depth-mm": ("1e-300",),
    "--sutures": ("201", "1000000000", str(2**62)),
    "--spacing-mm": ("1e-12", "5e-324", "0.001"),
    "--bite-width-mm": ("5e-324", "1e-9", "1e6"),
    "--bite-depth-mm": ("1e-300",),
}


def _fusiform_sweep(**grid: list[float]) -> Callable[[Path], list[str]]:
    doc = copy.deepcopy(demo_doc())
    doc["grid"].update(grid)
    doc["shapes"] = {"fusiform": {"wound_length_factor": [3], "wound_depth_factor": [0.5]}}

    def setup(ws: Path) -> list[str]:
        (ws / "s.yaml").write_text(yaml.safe_dump(doc))
        return ["generate", "s.yaml", "--out", "new"]

    return setup


# Outputs that would land on the store's files (each names --out).
_STORE_TARGETS = (
    "RUN/fields/0123456789abcdef.h5",
    "RUN/fields/mesh-0123456789abcdef.h5",
    "RUN/results/job-0123456789abcdef.parquet",
    "RUN/logs/x.h5",
    "RUN/tmp/x.h5",
    "RUN/corrupt/x.h5",
    "RUN/meshes/x.h5",
    "RUN/manifest.parquet",
    "RUN/sweep.yaml",
)

# An unknown option before the required arguments: click names the option, not the
# arguments given after it.
_UNKNOWN_FIRST = {
    "view": ["view", "--bogus", "RUN", "--out", "v.html"],
    "export": ["export", "--bogus", "RUN", "--all", "--out", "exp"],
    "solve": ["solve", "--bogus", "RUN", "--job", "0"],
    "mesh": ["mesh", "--bogus", "RUN", "--job", "0"],
    "generate": ["generate", "--bogus", "s.yaml", "--out", "new"],
    "slurm": ["slurm", "--bogus", "RUN", "--shards", "2"],
    "converge": ["converge", "--bogus", "RUN", "--job", "0"],
    "run": ["run", "--bogus", "RUN"],
    "case": ["case", "--bogus", "--out", "case-report"],
}


def round4_cases() -> list[Case]:
    cases = [
        Case(f"r4-case{opt}-{v}", _case(opt, v))
        for opt, values in _CASE_UNBOUNDED.items()
        for v in values
    ]
    for shard in ("0/1000000000", "0/33", f"0/{2**62}"):  # the demo run has 32 jobs
        cases.append(
            Case(
                f"r4-run-shard-{shard}", _in_run("run", "RUN", "--shard", shard), contains="shards"
            )
        )
    for i, width in enumerate((1e-6, 1e-9, 5e-324)):
        cases.append(
            Case(
                f"r4-fusiform-width-{i}",
                _fusiform_sweep(wound_width_factor=[width]),
                watch="new",
                contains="wound_width_mm",
            )
        )
    cases.append(Case("r4-fusiform-patch", _fusiform_sweep(patch_size_factor=[1e5]), watch="new"))
    for extra in (["--factors", "2"],):
        argv = ["converge", "RUN", "--job", "0", "--refine", "3", *extra]
        cases.append(Case(f"r4-converge-refine-3-{extra[1]}", _in_run(*argv), contains="cells"))
    for target in _STORE_TARGETS:
        name = target.removeprefix("RUN/").replace("/", "-")
        cases.append(
            Case(
                f"r4-solve-out-{name}",
                _in_run("solve", "RUN", "--job", "0", "--out", target),
                contains="inside the store",
            )
        )
    for cmd, target in (
        ("mesh", "RUN/fields/m.vtu"),
        ("view", "RUN/fields/v.html"),
        ("export", "RUN/results/exp"),
        ("mesh", "RUN/meshes/m.vtu"),
        ("view", "RUN/logs/v.html"),
    ):
        argv = [cmd, "RUN", "--job", "0", "--out", target]
        name = f"r4-{cmd}-out-{target.removeprefix('RUN/').replace('/', '-')}"
        cases.append(Case(name, _in_run(*argv), contains="inside the store"))
    for i, data in enumerate((b"{", b"[]", b'{"submissions": 5}', b"\xff\xfe")):
        prep = _slurm_record(data)
        argv = ["slurm", "RUN", "--shards", "2", "--submit"]
        cases.append(Case(f"r4-slurm-damaged-jobs-json-{i}", _in_run(*argv, prep=prep)))
    for cmd, argv in _UNKNOWN_FIRST.items():
        cases.append(Case(f"r4-unknown-option-first-{cmd}", _in_run(*argv), contains="--bogus"))
    return cases


def _slurm_record(data: bytes) -> Callable[[Path], None]:
    def prep(rd: Path) -> None:
        (rd / "slurm").mkdir()
        _write("slurm/jobs.json", data)(rd)

    return prep


ROUND4_CASES = round4_cases()
