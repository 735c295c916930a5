"""The bad inputs fed through the CLI by test_bad_inputs.py, one `Case` each.

A case's ``setup(ws)`` prepares the workspace ``ws`` (which holds a copy of the generated demo
run at ``ws/run``) and returns the argv to run there: broken sweep files (every grid axis,
ranges, structure, YAML, exclusion rules, material/stage/solver/analysis settings), files that
are not sweep files, bad output directories and damaged run directories, out-of-range command
options, and bad `predict` inputs. ``code`` is the exit status expected, ``watch`` the directory
that must stay unchanged, ``contains`` a word the one line on stderr must hold.
"""

from __future__ import annotations

import copy
import os
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import yaml
from cli_run import demo_doc

DEMO = demo_doc()


class Case(NamedTuple):
    """``setup(ws)`` prepares the workspace and returns argv; the CLI runs in ``ws``."""

    id: str
    setup: Callable[[Path], list[str]]
    code: int = 2
    fsize: int | None = None
    watch: str = "run"  # the directory that must stay unchanged (relative to ws)
    contains: str = ""  # a word the one line must hold


def _sweep(edit: Callable[[dict], None] | None = None, text: str | None = None) -> Callable:
    def setup(ws: Path) -> list[str]:
        if text is not None:
            (ws / "s.yaml").write_text(text)
        else:
            doc = copy.deepcopy(DEMO)
            edit(doc)  # type: ignore[misc]
            (ws / "s.yaml").write_text(yaml.safe_dump(doc))
        return ["generate", "s.yaml", "--out", "new"]

    return setup


def _set(path: str, value: Any) -> Callable[[dict], None]:
    keys = path.split(".")

    def edit(doc: dict) -> None:
        d = doc
        for k in keys[:-1]:
            d = d.setdefault(k, {})
        d[keys[-1]] = value

    return edit


def _delete(path: str) -> Callable[[dict], None]:
    keys = path.split(".")

    def edit(doc: dict) -> None:
        d = doc
        for k in keys[:-1]:
            d = d[k]
        del d[keys[-1]]

    return edit


def sweep_cases() -> list[Case]:
    cases = []
    bad_numbers: list[Any] = [float("nan"), float("inf"), -float("inf"), 10**400, True, "x", [1]]
    axes = list(DEMO["grid"])
    for axis in axes:
        values: list[Any] = [[], "1", None, [1, 1]] + [[v] for v in bad_numbers]
        if axis != "orientation_deg":
            values += [[0], [-1]]
        if axis == "skin_type":
            values = [[], "stiff", None, ["stiff", "stiff"], [1], ["nosuch"], [""], [None]]
        for i, v in enumerate(values):
            cases.append(Case(f"grid.{axis}-{i}", _sweep(_set(f"grid.{axis}", v)), watch="new"))
        cases.append(Case(f"grid.{axis}-missing", _sweep(_delete(f"grid.{axis}")), watch="new"))
    ranges = {
        "grid.mesh_size_factor": [1.5],
        "grid.wound_width_factor": [2.5],
        "shapes.wedge.wound_depth_factor": [1.0],
        "shapes.cylindrical.wound_aspect_factor": [-0.1],
    }
    for key, v in ranges.items():
        cases.append(Case(f"range-{key}", _sweep(_set(key, v)), watch="new"))
    structure = {
        "top-list": "- 1\n- 2\n",
        "top-scalar": "42\n",
        "top-empty": "",
        "top-unknown": yaml.safe_dump({**DEMO, "gird": {}}),
        "no-grid": yaml.safe_dump({k: v for k, v in DEMO.items() if k != "grid"}),
        "no-shapes": yaml.safe_dump({k: v for k, v in DEMO.items() if k != "shapes"}),
        "shapes-unknown": yaml.safe_dump({**DEMO, "shapes": {"round": {"x": [1]}}}),
        "shapes-empty": yaml.safe_dump({**DEMO, "shapes": {}}),
        "shapes-list": yaml.safe_dump({**DEMO, "shapes": ["wedge"]}),
        "shapes-wrong-axis": yaml.safe_dump({**DEMO, "shapes": {"wedge": {"depth": [0.3]}}}),
        "grid-list": yaml.safe_dump({**DEMO, "grid": [1, 2]}),
        "grid-unknown-axis": yaml.safe_dump({**DEMO, "grid": {**DEMO["grid"], "colour": [1]}}),
        "yaml-unclosed": "grid: [1, 2\n",
        "yaml-tab": "grid:\n\t- 1\n",
        "yaml-alias": "grid: *nowhere\n",
        "yaml-unhashable-key": "? [a, b]\n: 1\n",
        "yaml-deep": "[" * 20000 + "]" * 20000 + "\n",
        "yaml-deep-map": "a: " + "{a: " * 5000 + "1" + "}" * 5000 + "\n",
    }
    for name, text in structure.items():
        cases.append(Case(f"sweep-{name}", _sweep(text=text), watch="new"))
    rules = [
        "skin_type > 1", "skin_type + 1 > 2", "wound_shape == 1", "wound_width_mm",
        "not wound_width_mm", "'a' + 'b' == 'ab'", "wound_width_mm > 'x'",
        "(wound_width_mm > 1) + 1 > 0", "skin_type < 'z'", "wound_width_mm > 1 and 2",
        "-skin_type > 0", "wound_width_mm > 1 or 'x'", "skin_type", "open('x')",
        "wound_width_mm.real > 0", "[x for x in y]", "lambda: 1", "nosuch > 1",
        "wound_width_mm >", "(" * 300 + "1 > 0" + ")" * 300, "job_id == 'x'",
        "wound_width_mm > 0",  # excludes every job
        "1 ** 2 > 0", "wound_width_mm if 1 else 2", "None == None",
    ]  # fmt: skip
    for i, rule in enumerate(rules):
        cases.append(Case(f"rule-{i}", _sweep(_set("exclude", [rule])), watch="new"))
    cases.append(Case("rule-not-list", _sweep(_set("exclude", "a > 1")), watch="new"))
    cases.append(Case("rule-number", _sweep(_set("exclude", [5])), watch="new"))
    settings = {
        "materials.subcutis.C10_kPa": [-1, float("nan"), "abc", 0, [1], 10**400],
        "materials.subcutis.nope": [1],
        "materials.skin_types.stiff.mu_kPa": [[1, 2], "x", [1, 2, float("inf")]],
        "materials.skin_types.stiff.K_kPa": [float("inf")],
        "materials.skin_types.newskin": [{"c_kPa": 1}, 5, [1]],
        "materials.skin_types": [[1, 2], "x"],
        "materials": [[1], "x"],
        "stages.contact_model": ["smooth", "depth", 1],
        "stages.closure_load": ["x", 1, {"a": 1}],
        "stages.closure_zone.y_fraction": [2, 0, float("nan")],
        "stages.contact_penalty_GPa": [[-1, 5, 100], [1, 5], "x"],
        "stages.nope": [1],
        "solver.quadrature_degree": [1.5, -1, "x"],
        "solver.element_degree": [0, 3, 1.5, "x"],
        "solver.max_iterations": [-1, 2.5],
        "solver.rtol": [float("nan"), 0, -1e-8, float("inf")],
        "solver.nope": [1],
        "analysis.seed": ["x", -1],
        "analysis.nope": [1],
        "solver": [[1], "x"],
    }
    for key, values in settings.items():
        for i, v in enumerate(values):
            cases.append(Case(f"{key}-{i}", _sweep(_set(key, v)), watch="new"))
    cases += bounded_sweep_cases()
    return cases


def _alias_bomb(levels: int) -> str:
    """A sweep whose name is ``levels`` nested aliases of ten each (10**levels strings)."""
    lines = ['a0: &a0 "lol"']
    for k in range(1, levels + 1):
        lines.append(f"a{k}: &a{k} [" + ", ".join([f"*a{k - 1}"] * 10) + "]")
    return "\n".join(lines) + f"\nname: *a{levels}\n"


def bounded_sweep_cases() -> list[Case]:
    """Values of the right type outside their physical or numerical range, duplicate keys,
    aliases, and text where a name belongs."""
    text = yaml.safe_dump(DEMO)
    structure = {
        "yaml-duplicate-top-key": text + yaml.safe_dump({"grid": DEMO["grid"]}),
        "yaml-duplicate-nested-key": text.replace("grid:\n", "grid:\n  orientation_deg: [45]\n", 1),
        "yaml-alias-bomb-9": _alias_bomb(9),
        "yaml-alias-bomb-6": _alias_bomb(6),
        "yaml-alias-rules": "r: &r wound_width_mm > 100\n"
        + text.replace("exclude:", "exclude: [" + ", ".join(["*r"] * 5000) + "]\nold_exclude:", 1),
        "yaml-alias-grid": text.replace("grid:", "grid: &g", 1) + "shapes2: *g\n",
        "rule-400-digits": yaml.safe_dump({**DEMO, "exclude": ["wound_width_mm > " + "9" * 400]}),
        "rule-1e999": yaml.safe_dump({**DEMO, "exclude": ["wound_width_mm > 1e999"]}),
        "rule-too-many": yaml.safe_dump({**DEMO, "exclude": ["wound_width_mm > 100"] * 1001}),
        "rule-too-long": yaml.safe_dump({**DEMO, "exclude": ["wound_width_mm > 1" + " " * 1000]}),
    }
    cases = [Case(f"sweep-{k}", _sweep(text=v), watch="new") for k, v in structure.items()]
    full = {"c_kPa": 21.3, "mu_kPa": [17.8, 5.9, 5.9], "lambda11_kPa": 1.0,
            "lambda_other_kPa": 1.0, "K_kPa": 250, "tsf": 1.1}  # fmt: skip
    values = {
        "name": [[1], {"a": 1}, 5, "x" * 201, "two\nlines"],
        "description": [5, ["a"], "x" * 10_001],
        "materials.subcutis.K_kPa": [1e300, 1e-300],
        "materials.subcutis.C10_kPa": [1e-300],
        "materials.skin_types.stiff.tsf": [0.5, 1e6, 0.99],
        "materials.skin_types.stiff.c_kPa": [1e300, 1e-3],
        "materials.skin_types.stiff.mu_kPa": [[1e9, 11.8, 11.8]],
        "materials.skin_types.stiff.K_kPa": [1e300],
        "materials.skin_types.newskin": [{**full, "K_kPa": 1e-300}, {**full, "tsf": 3}],
        "stages.contact_penalty_GPa": [[100, 5, 1], [1, 1, 5], [1, 5, 1e9], [1e-9, 5, 100]],
        "solver.max_iterations": [0, 10**6],
        "solver.max_stage_iterations": [0, 10**9],
        "solver.quadrature_degree": [0, 1000, 7],  # P2 takes up to 6
        "solver.load_steps": [0],
        "solver.max_load_cuts": [1000],
        "solver.gamma_min": [5, 1e-300],
        "solver.rtol": [0.9],
        "solver.residual_growth": [0.5],
        "solver.divergence_factor": [0.5],
        "solver.max_strain_step": [1e9],
        "analysis.seed": [2**70, 2**32],
        "analysis.quantiles": [1, 1000],
        "analysis.n_estimators": [0, 10**9],
        "analysis.max_depth": [1000],
        "analysis.nthread": [0],
        "analysis.learning_rate": [5],
        "analysis.sobol_samples": [100, 2**30],
        "analysis.train_fraction": [0.99],
        "grid.patch_size_factor": [[1e6]],
        "grid.dermal_thickness_mm": [[1e300]],
    }
    for key, vals in values.items():
        for i, v in enumerate(vals):
            cases.append(Case(f"bounded-{key}-{i}", _sweep(_set(key, v)), watch="new"))
    return cases


def _raw(data: bytes) -> Callable[[Path], list[str]]:
    def setup(ws: Path) -> list[str]:
        (ws / "s.yaml").write_bytes(data)
        return ["generate", "s.yaml", "--out", "new"]

    return setup


def _special(kind: str) -> Callable[[Path], list[str]]:
    def setup(ws: Path) -> list[str]:
        p = ws / "s.yaml"
        if kind == "fifo":
            os.mkfifo(p)
        elif kind == "dir":
            p.mkdir()
        elif kind == "socket":
            s = socket.socket(socket.AF_UNIX)
            s.bind(str(p))  # left bound until the process ends: the case only stats it
        elif kind == "loop":
            p.symlink_to(p)
        elif kind == "missing":
            pass
        else:
            return ["generate", kind, "--out", "new"]
        return ["generate", "s.yaml", "--out", "new"]

    return setup


def file_cases() -> list[Case]:
    text = yaml.safe_dump(DEMO)
    rng = np.random.default_rng(0)
    raw = {
        "binary": rng.integers(0, 256, 4096, dtype=np.uint8).tobytes(),
        "nul": text.encode() + b"\0",
        "utf16le": text.encode("utf-16"),
        "utf16be": b"\xfe\xff" + text.encode("utf-16-be"),
        "utf32": text.encode("utf-32"),
        "latin1": ("# caf\xe9\n" + text).encode("latin-1"),
        "huge": b"# " + b"x" * 1_100_000 + b"\n" + text.encode(),
        "gzip": b"\x1f\x8b\x08\x00" + bytes(100),
    }
    cases = [Case(f"file-{k}", _raw(v), watch="new") for k, v in raw.items()]
    for kind in ("fifo", "dir", "socket", "loop", "missing", "/dev/zero", "/dev/null",
                 "/dev/urandom", "/proc/self/status", "/proc/self/mem"):  # fmt: skip
        cases.append(Case(f"file-{kind}", _special(kind), watch="new"))
    return cases


def _in_run(*argv: str, prep: Callable[[Path], None] | None = None) -> Callable:
    """A case over a copy of the template run at ws/run."""

    def setup(ws: Path) -> list[str]:
        if prep is not None:
            prep(ws / "run")
        return [a.replace("RUN", str(ws / "run")) for a in argv]

    return setup


def truncate_manifest(rd: Path) -> None:
    p = rd / "manifest.parquet"
    p.write_bytes(p.read_bytes()[:-100])


def _write(name: str, data: bytes) -> Callable[[Path], None]:
    def prep(rd: Path) -> None:
        (rd / name).write_bytes(data)

    return prep


def _demo_file(ws: Path) -> None:
    (ws / "demo.yaml").write_text(yaml.safe_dump(DEMO))


def _gen(*extra: str, prep: Callable[[Path], None] | None = None, doc: dict | None = None):  # type: ignore[no-untyped-def]
    def setup(ws: Path) -> list[str]:
        (ws / "s.yaml").write_text(yaml.safe_dump(doc or DEMO))
        if prep is not None:
            prep(ws)
        return ["generate", "s.yaml", *[a.replace("WS", str(ws)) for a in extra]]

    return setup


def _file_at(rel: str) -> Callable[[Path], None]:
    def prep(ws: Path) -> None:
        (ws / rel).write_text("not a directory")

    return prep


BIGGER = {**DEMO, "grid": {**DEMO["grid"], "orientation_deg": [0, 90]}}
HUGE = {  # 20 * 20 * 20 * 2 skin types * 200 orientations * (2 + 2) shape values
    **DEMO,
    "grid": {**DEMO["grid"], "dermal_thickness_mm": list(range(1, 21)),
             "patch_size_factor": list(range(1, 21)),
             "wound_width_factor": [k / 100 for k in range(1, 21)],
             "orientation_deg": list(range(200))},
}  # fmt: skip


def run_dir_cases() -> list[Case]:
    cases = [
        Case("gen-out-under-file", _gen("--out", "WS/f/run", prep=_file_at("f")), watch="f"),
        Case("gen-out-is-file", _gen("--out", "WS/f", prep=_file_at("f")), watch="f"),
        Case("gen-out-proc", _gen("--out", "/proc/woundsweep-test/run"), watch="none"),
        Case("gen-out-sys", _gen("--out", "/sys/woundsweep-test"), watch="none"),
        Case("gen-out-disk-full", _gen("--out", "WS/new"), fsize=2000, watch="none"),
        Case("gen-max-jobs", _gen("--out", "WS/new", "--max-jobs", "10"), watch="new"),
        Case("gen-max-jobs-0", _gen("--out", "WS/new", "--max-jobs", "0"), watch="new"),
        Case("gen-max-jobs-nan", _gen("--out", "WS/new", "--max-jobs", "nan"), watch="new"),
        Case("gen-huge-grid", _gen("--out", "WS/new", doc=HUGE), watch="new", contains="12800000 jobs"),
        Case("gen-other-sweep", _gen("--out", "WS/run", doc=BIGGER), contains="--force"),
        Case("gen-truncated-manifest", _gen("--out", "WS/run", prep=lambda ws: truncate_manifest(ws / "run")), contains="--force"),
        Case("gen-garbage-manifest", _gen("--out", "WS/run", prep=lambda ws: _write("manifest.parquet", b"PAR1junkPAR1")(ws / "run"))),
        Case("gen-no-manifest", _gen("--out", "WS/run", prep=lambda ws: (ws / "run" / "manifest.parquet").unlink())),
        Case("gen-garbage-sweep-copy", _gen("--out", "WS/run", prep=lambda ws: _write("sweep.yaml", b"\0\1\2")(ws / "run"))),
    ]  # fmt: skip
    run_opts = {
        "--timeout": ["nan", "inf", "-inf", "-1", "0", "abc", "1e300"],
        "--max-memory": ["nan", "inf", "0", "-1", "1e300", "x"],
        "--jit-stale-after": ["nan", "inf", "0"],
        "--workers": ["0", "-1", "x", "1.5", "1000000000"],
        "--retries": ["-1", "x"],
        "--stages": ["0-7", "3-1", "x", "7", "1-", "nan"],
        "--shard": ["2/2", "-1/2", "x", "1/0", "0/nan", "0/1/2"],
        "--fields": ["some"],
    }
    for opt, values in run_opts.items():
        for i, v in enumerate(values):
            cases.append(Case(f"run{opt}-{i}", _in_run("run", "RUN", "--no-progress", opt, v)))
    for cmd in ("run", "status", "slurm", "mesh", "solve"):
        extra = {"slurm": ["--shards", "2"], "mesh": ["--all"], "solve": ["--job", "0"]}.get(
            cmd, []
        )
        cases += [
            Case(f"{cmd}-not-a-run", _in_run(cmd, "RUN/results", *extra), watch="run"),
            Case(f"{cmd}-missing", _in_run(cmd, "RUN/nosuch", *extra)),
            Case(f"{cmd}-is-file", _in_run(cmd, "RUN/sweep.yaml", *extra)),
            Case(f"{cmd}-garbage-manifest", _in_run(cmd, "RUN", *extra, prep=_write("manifest.parquet", b"junk"))),
            Case(f"{cmd}-binary-sweep-copy", _in_run(cmd, "RUN", *extra, prep=_write("sweep.yaml", b"\xff\xfe\0x"))),
        ]  # fmt: skip
    slurm = {
        "--shards": ["0", "-1", "x", "1000"],
        "--cpus-per-task": ["0", "-2"],
        "--time": ["1h", "00:00:00", "25:61:00", "x", ""],
        "--mem": ["0", "4X", "1K", "10M", "99999999999T", "-1G", "nan"],
        "--partition": ["a b", 'x"y'],
        "--account": ["a%b"],
        "--extra": ["--qos=x\n#SBATCH --y", "rm -rf /"],
        "--stages": ["0-9", "x"],
        "--cache-dir": ["/tmp/with space"],
    }
    for opt, values in slurm.items():
        for i, v in enumerate(values):
            args = ["slurm", "RUN", opt, v] + ([] if opt == "--shards" else ["--shards", "2"])
            cases.append(Case(f"slurm{opt}-{i}", _in_run(*args)))
    cases.append(Case("slurm-mem-per-worker", _in_run("slurm", "RUN", "--shards", "2", "--mem", "100M", "--cpus-per-task", "4")))  # fmt: skip
    solve_mesh = [
        ("solve-out-proc", ["solve", "RUN", "--job", "0", "--out", "/proc/ws/x.h5"]),
        ("solve-out-dir", ["solve", "RUN", "--job", "0", "--out", "RUN"]),
        ("solve-out-under-file", ["solve", "RUN", "--job", "0", "--out", "RUN/sweep.yaml/x.h5"]),
        ("solve-stages", ["solve", "RUN", "--job", "0", "--stages", "0-9"]),
        ("solve-job-x", ["solve", "RUN", "--job", "x"]),
        ("mesh-out-proc", ["mesh", "RUN", "--job", "0", "--out", "/proc/ws/x.vtu"]),
        ("mesh-out-txt", ["mesh", "RUN", "--job", "0", "--out", "x.txt"]),
        ("mesh-no-selector", ["mesh", "RUN"]),
        ("mesh-job-range", ["mesh", "RUN", "--job", "9999"]),
        ("mesh-geometry", ["mesh", "RUN", "--geometry", "nosuch"]),
    ]
    for name, argv in solve_mesh:
        cases.append(Case(name, _in_run(*argv)))
    for sub in ("results", "slurm", "fields"):
        cmd = ["slurm", "RUN", "--shards", "2"] if sub == "slurm" else ["run", "RUN"]
        cases.append(Case(f"{cmd[0]}-{sub}-is-a-file", _in_run(*cmd, prep=_write(sub, b"x"))))
    analyze = [
        ("analyze-param-nan", ["analyze", "RUN", "--param", "learning_rate=nan"]),
        ("analyze-param-junk", ["analyze", "RUN", "--param", "junk"]),
        ("analyze-quantiles-0", ["analyze", "RUN", "--quantiles", "0"]),
        ("analyze-no-results", ["analyze", "RUN"]),
        ("analyze-not-a-run", ["analyze", "RUN/nosuch"]),
    ]
    for name, argv in analyze:
        cases.append(Case(name, _in_run(*argv)))
    outputs = [  # missing output directories are created; a file in the way is refused
        ("view-out-under-file", ["view", "RUN", "--job", "0", "--out", "RUN/sweep.yaml/x.html"], "sweep.yaml is not a directory"),
        ("view-out-proc", ["view", "RUN", "--job", "0", "--out", "/proc/ws/x.html"], "--out"),
        ("export-out-is-file", ["export", "RUN", "--job", "0", "--out", "RUN/sweep.yaml"], "is a file"),
        ("export-out-under-file", ["export", "RUN", "--all", "--out", "RUN/sweep.yaml/d"], "sweep.yaml is not a directory"),
        ("atlas-out-is-file", ["atlas", "RUN", "--out", "RUN/sweep.yaml"], "is a file"),
        ("atlas-out-under-file", ["atlas", "RUN", "--out", "RUN/sweep.yaml/site"], "sweep.yaml is not a directory"),
        ("mesh-out-under-file", ["mesh", "RUN", "--job", "0", "--out", "RUN/sweep.yaml/m.vtu"], "sweep.yaml is not a directory"),
        ("view-no-result", ["view", "RUN", "--job", "0", "--out", "v.html"], "no stored result"),
        ("export-no-result", ["export", "RUN", "--job", "0", "--out", "exp"], "no stored result"),
        ("view-result-not-hdf5", ["view", "RUN", "--result", "RUN/sweep.yaml", "--out", "v.html"], "sweep.yaml"),
        ("export-result-missing", ["export", "RUN", "--result", "RUN/nosuch.h5", "--out", "exp"], "nosuch.h5"),
        ("view-neither-job-nor-result", ["view", "RUN", "--out", "v.html"], "--job N or --result"),
        ("view-missing-all", ["view"], "RUN_DIR, --out"),
        ("export-missing-all", ["export"], "RUN_DIR, --out"),
        ("solve-missing-all", ["solve"], "RUN_DIR, --job"),
        ("predict-missing-options", ["predict", "RUN", "--shape", "wedge"], "--dermal-thickness, --subcutis-thickness-factor"),
        ("predict-not-a-run", ["predict", "RUN/..", *PREDICT_ARGS], "not a run directory"),
    ]  # fmt: skip
    for name, argv, word in outputs:
        cases.append(Case(name, _in_run(*argv), contains=word))
    cases += bounded_run_cases()
    return cases


def _edit_manifest(edit: Callable[[Any], Any]) -> Callable[[Path], None]:
    def prep(rd: Path) -> None:
        import pandas as pd

        m = pd.read_parquet(rd / "manifest.parquet")
        m = edit(m)
        m.to_parquet(rd / "manifest.parquet", index=False)

    return prep


def _set_cell(col: str, value: Any, row: int = 3) -> Callable[[Any], Any]:
    def edit(m: Any) -> Any:
        m[col] = m[col].astype(object) if isinstance(value, str) else m[col]
        m.loc[row, col] = value
        return m

    return edit


def bounded_run_cases() -> list[Case]:
    """Hand-edited manifests, paths with control characters, and option values outside
    their bounds (converge, analyze, atlas)."""
    import pandas as pd

    manifests = {
        "job-id-path": _set_cell("job_id", "../../x"),
        "job-id-absolute": _set_cell("job_id", "/tmp/x"),
        "geometry-id-path": _set_cell("geometry_id", "../mesh"),
        "duplicate-row": lambda m: pd.concat([m, m.iloc[[5]]], ignore_index=True),
        "duplicate-index": _set_cell("job_index", 4, row=5),
        "derived-width": _set_cell("wound_width_mm", 9.0),
        "parameter-edited": _set_cell("dermal_thickness_mm", 3.0),
        "unknown-skin": _set_cell("skin_type", "leather"),
        "unknown-shape": _set_cell("wound_shape", "round"),
        "empty": lambda m: m.iloc[:0],
    }
    cases = []
    for name, edit in manifests.items():
        for cmd in (
            ["run", "RUN", "--no-progress"],
            ["status", "RUN"],
            ["mesh", "RUN", "--job", "3"],
        ):
            prep = _edit_manifest(edit)
            cases.append(
                Case(
                    f"manifest-{name}-{cmd[0]}",
                    _in_run(*cmd, prep=prep),
                    contains="damaged manifest",
                )
            )
    options = [
        ("converge-levels-5000", ["converge", "RUN", "--job", "0", "--levels", "5000"]),
        ("converge-levels-2", ["converge", "RUN", "--job", "0", "--levels", "2"]),
        ("converge-ratio-1+eps", ["converge", "RUN", "--job", "0", "--ratio", "1.0000000000000002"]),
        ("converge-ratio-nan", ["converge", "RUN", "--job", "0", "--ratio", "nan"]),
        ("converge-ratio-inf", ["converge", "RUN", "--job", "0", "--ratio", "inf"]),
        ("converge-refine-9", ["converge", "RUN", "--job", "0", "--refine", "9"]),
        ("converge-factors-close", ["converge", "RUN", "--job", "0", "--factors", "0.3,0.3000001,0.31"]),
        ("converge-factors-many", ["converge", "RUN", "--job", "0", "--factors", ",".join(f"{0.1 * 1.1**k:.4f}" for k in range(12))]),
        ("analyze-seed-negative", ["analyze", "RUN", "--seed", "-5"]),
        ("analyze-seed-2**70", ["analyze", "RUN", "--seed", str(2**70)]),
        ("analyze-param-seed-2**70", ["analyze", "RUN", "--param", f"seed={2**70}"]),
        ("analyze-param-seed-1e400", ["analyze", "RUN", "--param", "seed=1e400"]),
        ("analyze-quantiles-1000", ["analyze", "RUN", "--quantiles", "1000"]),
        ("analyze-nthread-0", ["analyze", "RUN", "--nthread", "0"]),
        ("atlas-views-huge", ["atlas", "RUN", "--views", "0-99999999999999999"]),
        ("atlas-views-reversed", ["atlas", "RUN", "--views", "5-2"]),
        ("atlas-views-past-end", ["atlas", "RUN", "--views", "31-32"]),
        ("atlas-out-run-dir", ["atlas", "RUN", "--out", "RUN"]),
        ("atlas-out-results", ["atlas", "RUN", "--out", "RUN/results"]),
        ("atlas-out-parent", ["atlas", "RUN", "--out", "RUN/.."]),
        ("status-newline-path", ["status", "RUN/new\nline"]),
        ("run-newline-path", ["run", "RUN\n/x"]),
        ("generate-newline-sweep", ["generate", "RUN/s\nweep.yaml", "--out", "RUN/new"]),
        ("status-tab-cr-path", ["status", "RUN/a\tb\rc"]),
    ]  # fmt: skip
    for name, argv in options:
        cases.append(Case(name, _in_run(*argv)))
    return cases


PREDICT_BASE = {
    "--dermal-thickness": "1", "--subcutis-thickness-factor": "1", "--patch-size-factor": "2",
    "--wound-width-factor": "0.3", "--mesh-size-factor": "0.3", "--orientation": "0",
    "--wound-depth-factor": "0.3",
}  # fmt: skip


PREDICT_ARGS = ["--shape", "wedge", "--skin-type", "stiff"] + [
    a for k, v in PREDICT_BASE.items() for a in (k, v)
]


def _predict(opt: str | None, value: str, prep: Callable[[Path], None] | None = None):  # type: ignore[no-untyped-def]
    def setup(ws: Path) -> list[str]:
        if prep is not None:
            prep(ws)
        args = [
            "predict",
            str(ws / "model_geometry.json"),
            "--shape",
            "wedge",
            "--skin-type",
            "stiff",
        ]
        for k, v in PREDICT_BASE.items():
            args += [k, value if k == opt else v]
        return args

    return setup


def _model_meta(meta: bytes) -> Callable[[Path], None]:
    def prep(ws: Path) -> None:
        (ws / "model_geometry.json").write_text("{}")
        (ws / "model_geometry_meta.json").write_bytes(meta)

    return prep


def predict_cases() -> list[Case]:
    cases = []
    for opt in PREDICT_BASE:
        for v in ("nan", "inf", "-inf", "1e999", "x"):
            cases.append(Case(f"predict{opt}-{v}", _predict(opt, v), watch="none"))
    for i, meta in enumerate([b"null", b"[]", b"{", b'{"format": null}', b"\0\0"]):
        cases.append(Case(f"predict-meta-{i}", _predict(None, "", _model_meta(meta)), watch="none"))
    for opt in PREDICT_BASE:  # finite, but no wound: refused even with --allow-extrapolation
        for v in ("1e308", "-1e308", "1e7"):
            cases.append(
                Case(f"predict-extrapolated{opt}-{v}", _predict_extrapolated(opt, v), watch="none")
            )
    for v in ("nan", "inf", "x", "95", "-1"):  # the angle to the Langer line: 0-90 degrees
        cases.append(Case(f"predict--angle-to-langer-{v}", _predict_angle(v), watch="none"))
    both = _predict_angle("30", keep_orientation=True)
    cases.append(Case("predict-angle-and-orientation", both, watch="none", contains="exactly one"))
    return cases


def _predict_angle(value: str, keep_orientation: bool = False) -> Callable[[Path], list[str]]:
    """`predict` with ``--angle-to-langer value`` in place of (or beside) ``--orientation``."""

    def setup(ws: Path) -> list[str]:
        argv = _predict(None, "")(ws)
        if not keep_orientation:
            i = argv.index("--orientation")
            del argv[i : i + 2]
        return [*argv, "--angle-to-langer", value]

    return setup


def _predict_extrapolated(opt: str, value: str) -> Callable[[Path], list[str]]:
    def setup(ws: Path) -> list[str]:
        return [*_predict(opt, value)(ws), "--allow-extrapolation"]

    return setup


# `case`: every flag's bad values (each refused before anything is meshed or solved).
_CASE_BAD = {
    "--length-mm": ("nan", "inf", "-1", "0", "x", "1e999"),
    "--width-mm": ("nan", "-inf", "0", "20", "25", "x"),  # the length is 20
    "--angle-deg": ("nan", "-1", "90.5", "x"),
    "--site": ("moon",),
    "--dermis-mm": ("nan", "0", "-2", "x"),
    "--subcutis-mm": ("inf", "0", "x"),
    "--depth-mm": ("nan", "1", "7.5", "x"),  # within the dermis; through the 7.5 mm patch
    "--skin": ("leather",),
    "--sutures": ("0", "-3", "1.5", "x"),
    "--spacing-mm": ("nan", "0", "-3", "30", "x"),
    "--bite-width-mm": ("nan", "0", "-1", "x"),
    "--bite-depth-mm": ("nan", "0", "3.5", "x"),  # 3.5 mm reaches below the walls
    "--itch-strain": ("nan", "-0.1", "0.6", "x"),
    "--itch-angle-deg": ("nan", "181", "x"),
    "--itch-to-wound-deg": ("nan", "-181", "x"),
    "--itch-kind": ("twist",),
    "--element": ("3", "0", "x"),
    "--mesh-factor": ("nan", "0", "8.5", "x"),
}


def _case(opt: str, value: str) -> Callable[[Path], list[str]]:
    def setup(ws: Path) -> list[str]:
        return ["case", "--out", "case-report", opt, value]

    return setup


def case_cases() -> list[Case]:
    cases = [
        Case(f"case{opt}-{v}", _case(opt, v)) for opt, values in _CASE_BAD.items() for v in values
    ]

    def both(ws: Path) -> list[str]:
        return ["case", "--out", "o", "--sutures", "3", "--spacing-mm", "4"]

    def out_file(ws: Path) -> list[str]:
        (ws / "f").write_text("")
        return ["case", "--out", "f"]

    def two_directions(ws: Path) -> list[str]:
        return ["case", "--out", "o", "--itch-to-wound-deg", "45", "--itch-angle-deg", "30"]

    cases.append(Case("case-count-and-spacing", both, contains="spacing"))
    cases.append(Case("case-itch-two-directions", two_directions, contains="not both"))
    cases.append(Case("case-out-is-a-file", out_file, contains="--out"))
    return cases


CASES = sweep_cases() + file_cases() + run_dir_cases() + predict_cases() + case_cases()
