"""Small run directories for the runner and fork-server tests, and the processes working on
them: `make_run` generates the cheapest corner of the demo sweep (one coarse geometry, 9 jobs,
or two, 18 jobs); `solve_processes` lists the live `woundsweep solve` processes of a run."""

from __future__ import annotations

import json
from pathlib import Path

from cli_run import generate_run

FORKSERVER = b"woundsweep.execution.forkserver"

# One coarse geometry (9 jobs) or two (18 jobs): the cheapest corner of the demo sweep.
SWEEP = {
    "name": "runner-test",
    "grid": {
        "dermal_thickness_mm": [1],
        "subcutis_thickness_factor": [1],
        "patch_size_factor": [1],
        "wound_width_factor": [0.3],
        "mesh_size_factor": [0.3],
        "skin_type": ["stiff", "soft", "normal"],
        "orientation_deg": [0, 45, 90],
    },
    "shapes": {"cylindrical": {"wound_aspect_factor": [0]}, "wedge": {"wound_depth_factor": [0.3]}},
    "solver": {"element_degree": 1},
}


def make_run(tmp_path: Path, name: str, shapes: tuple[str, ...] = ("cylindrical",)) -> Path:
    sweep = json.loads(json.dumps(SWEEP))
    sweep["shapes"] = {k: v for k, v in sweep["shapes"].items() if k in shapes}
    return generate_run(sweep, tmp_path, name)


def solve_processes(rd: Path) -> list[int]:
    """Pids of live `woundsweep solve` processes working on ``rd``: a runner's fork server
    for ``rd`` and the job processes it forked (their command line is the server's)."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if {b"solve", FORKSERVER} & set(cmd) and str(rd).encode() in cmd:
                pids.append(int(d.name))
    return pids
