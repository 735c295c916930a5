"""Meshing time and cell counts of woundsweep.mesh.build.build_mesh.

Usage::

    python benchmarks/bench_geometry.py          # a fixed set of geometries (a few seconds)
    python benchmarks/bench_geometry.py --all    # every paper geometry (sweeps/paper.yaml)

The meshes are P1's (``element_degree`` 1: the finer node spacing). The fixed set spans both
shapes, the smallest and the largest patches and the three mesh size factors. ``--all`` builds
all 1,296 paper geometries once (single-threaded gmsh) and prints the cell-count
distribution (min / median / max, per mesh size factor), the worst element quality, whether
each geometry's cell count increases strictly with the mesh size factor, and whether any
geometry exceeds the paper's 40,000-cell cap. Exit status 1 if either check fails.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from woundsweep.config.geometry import GeometrySpec  # noqa: E402
from woundsweep.mesh.build import build_mesh  # noqa: E402
from woundsweep.mesh.sizing import PAPER_CELL_CAP  # noqa: E402

__all__ = ["main"]


def fixed_set() -> list[tuple[str, GeometrySpec]]:
    """Named geometries: (t_d, f_s, f_p, f_w, third factor) at the three mesh size factors."""
    cases = [
        ("cyl small", "cylindrical", 1.0, 0.5, 1, 0.5, 0.0),
        ("cyl large", "cylindrical", 1.0, 2.0, 3, 0.3, 0.1),
        ("wedge small deep", "wedge", 1.0, 0.5, 1, 0.3, 0.7),
        ("wedge large deep", "wedge", 1.0, 2.0, 3, 0.3, 0.7),
    ]
    out = []
    for name, shape, t_d, f_s, f_p, f_w, third in cases:
        T = t_d * (1 + f_s)
        L = f_p * T
        w = f_w * L
        for m in (0.3, 0.5, 0.7):
            if shape == "cylindrical":
                spec = GeometrySpec.cylindrical(t_d, f_s * t_d, L, w, third, m, element_degree=1)
            else:
                spec = GeometrySpec.wedge(t_d, f_s * t_d, L, w, third * T, m, element_degree=1)
            out.append((f"{name} m={m}", spec))
    return out


def run_fixed(repeats: int) -> None:
    print(f"{'geometry':<26}{'cells':>8}{'vertices':>10}{'min SICN':>10}{'time s':>9}")
    for name, spec in fixed_set():
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            mesh = build_mesh(spec)
            times.append(time.perf_counter() - t0)
        info = mesh.info
        print(
            f"{name:<26}{info['cells']:>8}{info['vertices']:>10}"
            f"{info['min_quality']:>10.3f}{min(times):>9.2f}"
        )


def run_all() -> int:
    from woundsweep.config.manifest import expand
    from woundsweep.config.sweep import load_sweep

    manifest = expand(load_sweep(ROOT / "sweeps" / "paper.yaml"))
    geoms = manifest.drop_duplicates("geometry_id").reset_index(drop=True)
    rows = []
    t_all = time.perf_counter()
    for i, row in geoms.iterrows():
        spec = GeometrySpec.from_row(row, None, 1)
        t0 = time.perf_counter()
        mesh = build_mesh(spec)
        rows.append((spec, mesh.info["cells"], mesh.info["min_quality"], time.perf_counter() - t0))
        if (i + 1) % 100 == 0:
            print(f"  {i + 1}/{len(geoms)} built", file=sys.stderr, flush=True)
    wall = time.perf_counter() - t_all
    cells = np.array([r[1] for r in rows])
    quality = np.array([r[2] for r in rows])
    times = np.array([r[3] for r in rows])
    factors = np.array([r[0].mesh_size_factor for r in rows])
    print(f"paper geometries: {len(rows)} built in {wall:.0f} s (mean {times.mean():.2f} s, "
          f"max {times.max():.2f} s per mesh)")  # fmt: skip
    print(f"cells over all: min {cells.min()}, median {int(np.median(cells))}, max {cells.max()}")
    for m in sorted(set(factors)):
        c = cells[factors == m]
        print(f"  mesh size factor {m:g}: min {c.min()}, median {int(np.median(c))}, "
              f"max {c.max()}")  # fmt: skip
    over = int((cells > PAPER_CELL_CAP).sum())
    print(f"above the {PAPER_CELL_CAP:,}-cell cap: {over}")
    print(f"min SICN: min {quality.min():.3f}, median {statistics.median(quality):.3f}; "
          f"below 0.1: {int((quality < 0.1).sum())}")  # fmt: skip
    worst = np.argsort(quality)[:5]
    for k in worst:
        print(f"  low quality {quality[k]:.3f}: {rows[k][0].describe()}")
    biggest = int(np.argmax(cells))
    print(f"largest: {cells[biggest]} cells, {rows[biggest][0].describe()}")
    # Strict monotonicity in the mesh size factor, geometry by geometry.
    keys = [c for c in geoms.columns if c.endswith("_factor") and c != "mesh_size_factor"]
    keys += ["wound_shape", "dermal_thickness_mm"]
    frame = geoms[keys].copy()
    frame["cells"], frame["m"] = cells, factors
    groups = frame.fillna(-1).groupby(keys)
    bad = sum(
        1 for _, g in groups if not np.all(np.diff(g.sort_values("m")["cells"].to_numpy()) > 0)
    )
    print(f"geometries whose cell count does not increase strictly with the factor: {bad} "
          f"of {groups.ngroups}")  # fmt: skip
    return 1 if over or bad else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--all", action="store_true", help="mesh every paper geometry")
    parser.add_argument("--repeats", type=int, default=1, help="builds per fixed geometry")
    args = parser.parse_args(argv)
    if args.all:
        return run_all()
    run_fixed(args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
