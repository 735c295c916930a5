"""The report of one clinical case (`woundsweep case`): report.md, case.json and figures.

- ``forces.png``: the force of each suture as placed, under the load after closure, at the
  evened placement and along the Langer line;
- ``view.png``: the sutured skin surface around the wound in 3D, the sutures drawn;
- ``wound.png``: along the wound, the surface gap (as sutured and at each step of the load),
  the contact pressure and the surface von Mises beside the edge, the sutures marked.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..config.sutures import BODY_SITES
from ..core.fsutil import atomic_write
from ..physics.closure import CLOSED_MAX_PER_W, CLOSED_MEDIAN_PER_W
from ..physics.suture_measures import SutureState
from .case import ITCH_STEPS, CaseResult, best_evened

__all__ = ["VIEW_Z_SCALE", "write_report"]

VIEW_Z_SCALE = 3.0


def _forces_row(st: SutureState) -> str:
    return ", ".join(f"{f:.0f}" for f in st.suture_force_mN)


def _positions(st: SutureState) -> str:
    return ", ".join(f"{y:+.1f}" for y in st.suture_y_mm)


def _opens_first(result: CaseResult) -> tuple[int, float, float] | None:
    """(load step, y, gap) of the first surface point closed after suturing (gap at most
    `CLOSED_MEDIAN_PER_W` of w) whose gap passes that bound under the load: the earliest step,
    and in it the largest gap; None if none opens."""
    before = result.sutured
    bound = CLOSED_MEDIAN_PER_W * before.closure.width_mm
    closed = before.gap_mm <= bound
    for j, step in enumerate(result.itch, 1):
        if step.state is None:
            return None
        opened = closed & (step.state.gap_mm > bound)
        if opened.any():
            i = int(np.argmax(np.where(opened, step.state.gap_mm, -np.inf)))
            return j, float(before.gap_y_mm[i]), float(step.state.gap_mm[i])
    return None


def _grows_most(result: CaseResult) -> tuple[float, float, float] | None:
    """(y, gap before, gap at the end of the load) of the surface point whose gap grows most."""
    last = next((s.state for s in reversed(result.itch) if s.state is not None), None)
    if last is None:
        return None
    grow = last.gap_mm - result.sutured.gap_mm
    i = int(np.argmax(grow))
    return float(last.gap_y_mm[i]), float(result.sutured.gap_mm[i]), float(last.gap_mm[i])


def _deviation(result: CaseResult) -> float:
    """The largest relative difference of a suture force or the dog-ear height between a
    level of the convergence check and the finest."""
    fine = result.levels[-1]
    dev = 0.0
    for lv in result.levels[:-1]:
        df = np.abs(lv.suture_force_mN / fine.suture_force_mN - 1)
        dev = max(dev, float(df.max()), abs(lv.dog_ear_height_mm / fine.dog_ear_height_mm - 1))
    return dev


def _summary(result: CaseResult) -> dict[str, Any]:
    c = result.case
    st = result.sutured
    out: dict[str, Any] = {
        "length_mm": c.length_mm,
        "width_mm": c.width,
        "angle_to_langer_deg": c.angle_deg,
        "dermal_thickness_mm": c.dermis,
        "subcutis_thickness_mm": c.subcutis,
        "depth_mm": c.depth,
        "skin_type": c.skin_type,
        "dofs": result.dofs,
        "element_degree": c.element_degree,
        "mesh_size_factor": c.mesh_size_factor,
        "time_s": result.time_s,
        "closing_force_mN": result.closing_force_mN,
        "suture_y_mm": st.suture_y_mm.tolist(),
        "suture_force_mN": st.suture_force_mN.tolist(),
        "closed": bool(st.closure.closed),
        "gap_max_mm": st.closure.gap_max_mm,
        "dog_ear_height_mm": st.dog_ear_height_mm,
        "itch": [
            None if s.state is None else {
                "status": s.status,
                "suture_force_mN": s.state.suture_force_mN.tolist(),
                "gap_max_mm": s.state.closure.gap_max_mm,
                "closed": bool(s.state.closure.closed),
                "dog_ear_height_mm": s.state.dog_ear_height_mm,
            }
            for s in result.itch
        ],
    }  # fmt: skip
    best = best_evened(result)
    if best is not None:
        out["evened_y_mm"] = best.suture_y_mm.tolist()
        out["evened_force_mN"] = best.suture_force_mN.tolist()
    out["evened_rounds"] = [
        {"suture_y_mm": s.suture_y_mm.tolist(), "suture_force_mN": s.suture_force_mN.tolist()}
        for s in result.evened
    ]
    if len(result.levels) > 1:
        out["mesh_levels"] = [
            {"mesh_size_factor": lv.mesh_size_factor, "dofs": lv.dofs,
             "suture_force_mN": lv.suture_force_mN.tolist(),
             "dog_ear_height_mm": lv.dog_ear_height_mm}
            for lv in result.levels
        ]  # fmt: skip
        out["mesh_max_deviation"] = _deviation(result)
    if result.along is not None:
        out["along_langer_force_mN"] = result.along.suture_force_mN.tolist()
        out["along_langer_closing_force_mN"] = result.along_closing_force_mN
        out["along_langer_dog_ear_height_mm"] = result.along.dog_ear_height_mm
    return out


def _figures(result: CaseResult, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    st = result.sutured
    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    n = len(st.suture_force_mN)
    x = np.arange(n)
    series = [("as placed", st)]
    last = next((s.state for s in reversed(result.itch) if s.state is not None), None)
    if last is not None:
        series.append(("under the load", last))
    best = best_evened(result)
    if best is not None:
        series.append(("evened placement", best))
    if result.along is not None:
        series.append(("along the Langer line", result.along))
    width = 0.8 / len(series)
    for k, (label, s) in enumerate(series):
        ax.bar(x + (k - (len(series) - 1) / 2) * width, s.suture_force_mN, width, label=label)
    ax.set_xticks(x, [f"{y:+.1f}" for y in st.suture_y_mm])
    ax.set_xlabel("suture position along the wound, as placed (mm)")
    ax.set_ylabel("suture force (mN)")
    ax.legend(fontsize=8)
    files = ["forces.png"]
    atomic_write(out / files[0], lambda tmp: fig.savefig(tmp, dpi=110, format="png"))

    fig = Figure(figsize=(7, 8), layout="constrained")
    a1, a2, a3 = fig.subplots(3, 1, sharex=True)
    a1.plot(st.gap_y_mm, st.gap_mm, "k.-", label="sutured")
    for j, step in enumerate(result.itch, 1):
        if step.state is not None:
            a1.plot(
                step.state.gap_y_mm, step.state.gap_mm, ".-", lw=0.8, label=f"load {j}/{ITCH_STEPS}"
            )
    a1.axhline(CLOSED_MAX_PER_W * st.closure.width_mm, color="r", ls=":", lw=0.8)
    a1.set_ylabel("surface gap (mm)")
    a1.legend(fontsize=7)
    a2.step(st.pressure_y_mm, st.contact_pressure_kPa, where="mid", color="k", label="sutured")
    if last is not None:
        a2.step(last.pressure_y_mm, last.contact_pressure_kPa, where="mid", label="under the load")
    a2.set_ylabel("largest contact\npressure (kPa)")
    a2.legend(fontsize=7)
    a3.plot(st.edge_y_mm, st.edge_von_mises_kPa, "k-", label="sutured")
    if last is not None:
        a3.plot(last.edge_y_mm, last.edge_von_mises_kPa, label="under the load")
    a3.set_ylabel("von Mises beside\nthe edge (kPa)")
    a3.set_xlabel("y along the wound (mm)")
    a3.legend(fontsize=7)
    for ax in (a1, a2, a3):
        for y in st.suture_y_mm:
            ax.axvline(y, color="0.8", lw=0.6, zorder=0)
    files.append("wound.png")
    atomic_write(out / files[1], lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    files.append(_view(result, out))
    return files


def _view(result: CaseResult, out: Path) -> str:
    """``view.png``: the sutured skin surface around the wound in 3D, coloured by its rise
    above the far field (the dog-ears at the apices), the sutures drawn between their bites;
    heights exaggerated `VIEW_Z_SCALE` times."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    sp = result.surface
    p = sp.points
    fig = Figure(figsize=(8, 6), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    tri = ax.plot_trisurf(
        p[:, 0], p[:, 1], p[:, 2], triangles=sp.triangles, cmap="viridis", linewidth=0.1,
        edgecolor=(0, 0, 0, 0.15), antialiased=True,
    )  # fmt: skip
    tri.set_array(sp.rise_mm[sp.triangles].mean(axis=1))
    tri.autoscale()
    for a, b in sp.sutures:
        ax.plot(*np.stack([a, b]).T, color="red", lw=3, zorder=10)
    span = np.ptp(p[:, :2], axis=0)
    ax.set_box_aspect((span[0], span[1], VIEW_Z_SCALE * max(float(np.ptp(p[:, 2])), 1e-3)))
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.view_init(elev=30, azim=-65)
    fig.colorbar(tri, ax=ax, shrink=0.6, label="rise above the far field (mm)")
    ax.set_title(f"sutured (red), heights x{VIEW_Z_SCALE:g}", fontsize=9)
    atomic_write(out / "view.png", lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    return "view.png"


def write_report(result: CaseResult, out: Path, command: str) -> Path:
    """Write report.md, case.json and the figures into ``out``; return report.md's path."""
    out.mkdir(parents=True, exist_ok=True)
    summary = _summary(result)
    atomic_write(out / "case.json", lambda tmp: Path(tmp).write_text(json.dumps(summary, indent=1)))
    figs = _figures(result, out)
    c, st = result.case, result.sutured
    w = st.closure.width_mm
    lines = [
        f"# Case: {c.length_mm:g} x {c.width:.3g} mm ellipse at {c.angle_deg:g} degrees to the Langer line",
        "",
        f"Command: `{command}`",
        "",
        f"Skin: {c.site} (dermis {c.dermis:g} mm, subcutis {c.subcutis:g} mm; "
        f"{BODY_SITES[c.site].source if c.dermal_thickness_mm is None else 'thicknesses given'}), "
        f"{c.skin_type} skin (Table 2). Excision {c.depth:.3g} mm deep. "
        f"{len(st.suture_y_mm)} simple interrupted sutures, bites {c.sutures.bite_width_mm:g} mm "
        f"from the edge, {c.sutures.depth(c.dermis):g} mm deep. Model: {result.dofs} dofs, "
        f"P{c.element_degree}, mesh size factor {c.mesh_size_factor:g}; solved in {result.time_s:.0f} s.",
        "",
        "## Forces per suture",
        "",
        "| suture | y (mm) | force (mN) | under the load (mN) | rise |",
        "|---|---|---|---|---|",
    ]
    last = next((s.state for s in reversed(result.itch) if s.state is not None), None)
    for i, (y, f) in enumerate(zip(st.suture_y_mm, st.suture_force_mN), 1):
        g = last.suture_force_mN[i - 1] if last is not None else float("nan")
        lines.append(f"| {i} | {y:+.1f} | {f:.0f} | {g:.0f} | {100 * (g / f - 1):+.0f} % |")
    lines += [
        "",
        f"Total {st.suture_force_mN.sum():.0f} mN (the Dirichlet closure's pull on one flank: "
        f"{result.closing_force_mN:.0f} mN). The wound is {'closed' if st.closure.closed else 'OPEN'} "
        f"(surface gap median {st.closure.gap_median_mm:.3f} mm, largest {st.closure.gap_max_mm:.3f} mm "
        f"of w = {w:.2f} mm; closed means at most {100 * CLOSED_MEDIAN_PER_W:g} % and "
        f"{100 * CLOSED_MAX_PER_W:g} % of w). Dog-ear height at the apices: "
        f"{st.dog_ear_mm[0]:.2f} and {st.dog_ear_mm[1]:.2f} mm.",
        "",
        "## Where to concentrate stitches",
        "",
    ]
    best = best_evened(result)
    spread = st.suture_force_mN.max() / max(st.suture_force_mN.min(), 1e-9)
    if best is not None:
        sp = best.suture_force_mN.max() / max(best.suture_force_mN.min(), 1e-9)
        dense = np.diff(best.suture_y_mm)
        mid = 0.5 * (best.suture_y_mm[1:] + best.suture_y_mm[:-1])
        i = int(np.argmin(dense))
        y_dense = float(np.round(mid[i], 1)) + 0.0  # + 0.0: no "-0.0" at the centre
        lines += [
            f"Concentrate stitches around y = {y_dense:+.1f} mm (spacing {dense[i]:.1f} mm there, "
            f"{dense.max():.1f} mm at the widest). Placed at {_positions(best)} mm, the forces "
            f"are {_forces_row(best)} mN: largest/smallest {sp:.2f} (as placed: {spread:.2f}).",
        ]
    else:
        lines += [
            f"No re-solved placement evened the forces better (largest/smallest {spread:.2f})."
        ]
    lines += ["", "## When the patient moves", ""]
    it = c.itch
    lines.append(
        f"Load: {it.kind} of {100 * it.strain:g} % at {it.angle_to_langer_deg:g} degrees to the "
        f"Langer line, applied to the patch's edges in {ITCH_STEPS} steps."
    )
    lines.append("")
    done = [s for s in result.itch if s.state is not None]
    if len(done) < len(result.itch) or not done:
        lines.append(
            f"The load could not be followed past step {len(done)}/{ITCH_STEPS} ({result.itch[-1].status})."
        )
    if last is not None:
        rise = last.suture_force_mN - st.suture_force_mN
        k = int(np.argmax(rise))
        lines.append(
            f"The suture at y = {st.suture_y_mm[k]:+.1f} mm gains most: {st.suture_force_mN[k]:.0f} -> "
            f"{last.suture_force_mN[k]:.0f} mN. The wound is "
            f"{'closed' if last.closure.closed else 'no longer closed: it REOPENS'} "
            f"(largest surface gap {last.closure.gap_max_mm:.3f} mm; dog-ears {last.dog_ear_height_mm:.2f} mm)."
        )
        first = _opens_first(result)
        bound = 100 * CLOSED_MEDIAN_PER_W
        if first is not None:
            lines.append(
                f"The closed flanks open first at y = {first[1]:+.2f} mm, at load step "
                f"{first[0]}/{ITCH_STEPS} (gap {first[2]:.3f} mm, past {bound:g} % of w)."
            )
        else:
            lines.append(f"No closed part of the wound opens past {bound:g} % of w under the load.")
        grow = _grows_most(result)
        if grow is not None:
            lines.append(
                f"The gap grows most at y = {grow[0]:+.2f} mm ({grow[1]:.3f} -> {grow[2]:.3f} mm), "
                "where the flanks would part first."
            )
    if result.along is not None:
        al = result.along
        lines += [
            "",
            "## The same wound along the Langer line",
            "",
            f"Forces {_forces_row(al)} mN (total {al.suture_force_mN.sum():.0f}, here "
            f"{st.suture_force_mN.sum():.0f}); Dirichlet closing pull {result.along_closing_force_mN:.0f} mN "
            f"(here {result.closing_force_mN:.0f}); dog-ears {al.dog_ear_height_mm:.2f} mm "
            f"(here {st.dog_ear_height_mm:.2f}).",
        ]
    if len(result.levels) > 1:
        lines += [
            "",
            "## Mesh convergence",
            "",
            "| mesh size factor | dofs | suture forces (mN) | dog-ear (mm) |",
            "|---|---|---|---|",
        ]
        for lv in result.levels:
            forces = ", ".join(f"{f:.1f}" for f in lv.suture_force_mN)
            lines.append(
                f"| {lv.mesh_size_factor:.4g} | {lv.dofs} | {forces} | {lv.dog_ear_height_mm:.3f} |"
            )
        lines += [
            "",
            f"Largest difference from the finest mesh: {100 * _deviation(result):.1f} % "
            f"({'within' if _deviation(result) <= 0.05 else 'ABOVE'} 5 %).",
        ]
    lines += ["", "## Figures", ""] + [f"![{f}]({f})" for f in figs] + [""]
    path = out / "report.md"
    atomic_write(path, lambda tmp: Path(tmp).write_text("\n".join(lines)))
    return path
