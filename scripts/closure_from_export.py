"""Closure of every exported stage, read from the ParaView files alone.

    python scripts/closure_from_export.py EXPORT_DIR [--median 0.01] [--max 0.05]

EXPORT_DIR is what `woundsweep export --all --out EXPORT_DIR` wrote. For each VTU (one job,
one stage) the closure zone's triangles (cell data ``closure_zone``) give the zone's vertices;
those on the skin surface (largest z) are split at the wound's mid-plane and paired with their
mirror images; the gap of a pair is the deformed x of the right vertex minus the left one's.
The zone is closed when the median gap is at most ``--median`` and the largest at most
``--max`` of the wound width (the reference distance of the widest surface pair). Prints one
line per stage with the counts, and exits 1 if a stage 3-6 VTU is open.

This reads only the exported mesh and displacement: an independent check of the store's
``closed`` column (it uses the vertices, not P2's edge nodes).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections import defaultdict
from pathlib import Path

import meshio
import numpy as np
from scipy.spatial import cKDTree


def closure(path: Path) -> tuple[float, float, float] | None:
    """(median gap / w, max gap / w, largest overlap / w) of one VTU, None without a zone."""
    m = meshio.read(path)
    X = m.points
    u = m.point_data["displacement_mm"]
    zone_nodes = []
    for block, flags in zip(m.cells, m.cell_data["closure_zone"]):
        if block.type == "triangle":
            zone_nodes.append(block.data[np.asarray(flags) > 0].ravel())
    nodes = np.unique(np.concatenate(zone_nodes)) if zone_nodes else np.zeros(0, dtype=int)
    if len(nodes) == 0:
        return None
    hi = X.max(axis=0)
    tol = 1e-9 * float(np.ptp(X, axis=0).max())
    x_c = 0.5 * (X[nodes, 0].min() + X[nodes, 0].max())
    left = nodes[X[nodes, 0] < x_c - tol]
    right = nodes[X[nodes, 0] > x_c + tol]
    image = X[left].copy()
    image[:, 0] = 2.0 * x_c - image[:, 0]
    dist, idx = cKDTree(X[right]).query(image)
    pairs = np.c_[left, right[idx]][dist < 1e-6 * float(np.ptp(X, axis=0).max())]
    x = X[:, 0] + u[:, 0]
    gap_all = x[pairs[:, 1]] - x[pairs[:, 0]]
    top = np.abs(X[pairs[:, 0], 2] - hi[2]) <= tol
    w = float((X[pairs[top, 1], 0] - X[pairs[top, 0], 0]).max())
    gap = gap_all[top]
    return float(np.median(gap)) / w, float(gap.max()) / w, max(0.0, -float(gap_all.min())) / w


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("export_dir", type=Path)
    ap.add_argument("--median", type=float, default=0.01)
    ap.add_argument("--max", type=float, default=0.05)
    args = ap.parse_args(argv)
    counts: dict[int, list[int]] = defaultdict(lambda: [0, 0])
    worst: dict[int, float] = defaultdict(float)
    overlap: dict[int, float] = defaultdict(float)
    for vtu in sorted(args.export_dir.glob("job-*/*.vtu")):
        m = re.search(r"stage[_-]?(\d)", vtu.name)
        if not m:
            continue
        res = closure(vtu)
        if res is None:
            continue
        stage = int(m.group(1))
        med, mx, ov = res
        closed = med <= args.median and mx <= args.max
        counts[stage][0] += int(closed)
        counts[stage][1] += 1
        worst[stage] = max(worst[stage], mx)
        overlap[stage] = max(overlap[stage], ov)
    bad = 0
    for stage in sorted(counts):
        c, n = counts[stage]
        print(
            f"stage {stage}: {c} of {n} closed; widest gap {worst[stage]:.4f} w; "
            f"largest overlap {overlap[stage]:.2e} w"
        )
        if stage >= 3:
            bad += n - c
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
