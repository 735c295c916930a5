"""Compare the per-stage results of one job solved on two DOLFINx versions.

Usage: python scripts/probes/compare_stage_results.py A.h5 B.h5 [--rtol 0.01]

Reads the `stage_results` JSON attribute of two `woundsweep solve` outputs (docs/design.md),
prints a table, and exits 1 if a stage's status differs or if a physics quantity that must
agree (maximal and volume-weighted 99th-percentile von Mises stress) differs by more than rtol
relative. Raw arrays (displacements per node, stresses per cell) are NOT compared: their order
depends on DOLFINx's cell/node reordering, which differs between versions.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

__all__ = ["compare", "main"]

CHECKED = ("max_von_mises_kPa", "p99_von_mises_kPa")
SHOWN = ("newton_iterations", "closure_gap_max_mm", "min_J", "contact_force_mN", "time_s")


def load(path: str) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    import h5py

    with h5py.File(path, "r") as f:
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
        cells = int(f["mesh/cells"].shape[0]) if "mesh/cells" in f else -1
    attrs["_cells"] = cells
    return attrs, json.loads(attrs["stage_results"])


def rel(a: float, b: float) -> float:
    if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)):
        return math.inf
    return abs(a - b) / max(abs(a), abs(b), 1e-300)


def compare(a_path: str, b_path: str, rtol: float) -> int:
    """Print the comparison; return the number of violations."""
    a_attrs, a_rows = load(a_path)
    b_attrs, b_rows = load(b_path)
    print(f"A: {a_path}  DOLFINx {a_attrs.get('dolfinx_version')}  cells {a_attrs['_cells']}")
    print(f"B: {b_path}  DOLFINx {b_attrs.get('dolfinx_version')}  cells {b_attrs['_cells']}")
    bad = 0
    if a_attrs.get("job_id") != b_attrs.get("job_id"):
        print(f"job_id differs: {a_attrs.get('job_id')} vs {b_attrs.get('job_id')}")
        bad += 1
    if a_attrs["_cells"] != b_attrs["_cells"]:
        print("note: different meshes (cell counts differ); tolerances may not be meaningful")
    b_by_stage = {r["stage"]: r for r in b_rows}
    for ra in a_rows:
        rb = b_by_stage.get(ra["stage"])
        if rb is None:
            print(f"stage {ra['stage']}: missing in B")
            bad += 1
            continue
        line = [f"stage {ra['stage']}: {ra['status']}/{rb['status']}"]
        if ra["status"] != rb["status"]:
            bad += 1
            line.append("STATUS DIFFERS")
        for key in CHECKED:
            d = rel(ra.get(key), rb.get(key))
            flag = "" if d <= rtol else " FAIL"
            bad += bool(flag)
            line.append(f"{key} {ra.get(key):.6g}/{rb.get(key):.6g} ({100 * d:.3f} %){flag}")
        for key in SHOWN:
            if key in ra:
                line.append(f"{key} {ra.get(key)}/{rb.get(key)}")
        print("  ".join(line))
    print(f"{'OK' if bad == 0 else 'FAILED'}: {bad} violation(s) at rtol {rtol}")
    return bad


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--rtol", type=float, default=0.01)
    args = p.parse_args(argv)
    return 1 if compare(args.a, args.b, args.rtol) else 0


if __name__ == "__main__":
    sys.exit(main())
