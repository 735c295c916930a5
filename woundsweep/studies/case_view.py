"""The 3D pictures of a clinical case (`woundsweep case`): ``view.png`` (`view_png`: the sutured
skin surface around the wound, its rise above the far field, the wound's rim and the threads)
and the fields of ``view.html`` (`woundsweep case --view`): `CaseView`, the mesh with the
sutured state's fields (and the state at the end of the load after closure), captured by
`run_case` only when asked (`capture_state` at the state, `case_view` at the end), and
`view_lines`, the threads and the rim as lines that move with the view's deformation scale.

A thread is drawn from bite to bite as a short arc above the skin (`thread_arc`), the visible
part of a simple interrupted suture: a drawing of where each suture holds (its bites, the top
surface's points nearest them), not the path of a thread through the skin.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..core.fsutil import atomic_write
from ..physics.suture_measures import bite_points, wound_rim

if TYPE_CHECKING:
    from ..physics.model import WoundModel
    from ..physics.suture_measures import SurfacePatch
    from ..physics.sutures import SuturedClosure

__all__ = [
    "THREAD_RISE",
    "VIEW_Z_SCALE",
    "CaseView",
    "Line3D",
    "ViewState",
    "capture_state",
    "case_view",
    "thread_arc",
    "view_lines",
    "view_png",
]

# view.png's heights are exaggerated this much; a thread's arc rises this fraction of its span.
VIEW_Z_SCALE = 3.0
THREAD_RISE = 0.25
_ARC_POINTS = 17


class ViewState(NamedTuple):
    """One state of the sutured wound on the case's mesh (input point and cell order)."""

    label: str
    displacement_mm: np.ndarray  # (n, 3) at the input points
    von_mises_kPa: np.ndarray  # (m,) cell means
    p99_von_mises_kPa: float  # of the volume (as a job's stage: `stress_summary`)
    max_von_mises_kPa: float  # the largest sample
    profile_points_mm: np.ndarray  # (lines, points, 3) `PROFILE_LINES`, reference
    profile_von_mises_kPa: np.ndarray  # (lines, points), NaN outside the mesh
    suture_y_mm: np.ndarray  # (s,)
    suture_force_mN: np.ndarray  # (s,)
    line_y_mm: np.ndarray | None = None  # bins along the wound: the sutures' pull per length
    closing_mN_per_mm: np.ndarray | None = None
    contact_mN_per_mm: np.ndarray | None = None


class CaseView(NamedTuple):
    """The case's mesh (input numbering), its wound's rim and sutures' bites, and states."""

    points_mm: np.ndarray  # (n, 3) reference
    cells: np.ndarray  # (m, 4)
    cell_tags: np.ndarray  # (m,)
    facets: np.ndarray  # (k, 3) the exterior triangles
    facet_tags: np.ndarray  # (k,)
    element_degree: int
    bites: np.ndarray  # (s, 2) per suture the top points of its two bites
    rim: np.ndarray  # (e, 2) the wound's rim at the skin surface (`wound_rim`)
    states: list[ViewState]


def _line_loads(m: WoundModel) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Along the wound the sutures' (the tie's) pull and the contact force per length."""
    line, tie, contact = m.closure_line, getattr(m, "tie", None), m.contact
    if line is None or tie is None or contact is None or not getattr(tie, "active", False):
        return None
    pull = -tie.force_vector(m.u, contact.k_V_kPa)  # +x toward the mid-plane on the left flank
    loads = line.line_loads(pull, m.contact_forces())
    return loads.y_mm, loads.closing_mN_per_mm, loads.contact_mN_per_mm


def capture_state(sc: SuturedClosure, label: str) -> ViewState:
    """The current state of ``sc`` for the view: displacement, cellwise von Mises with its
    p99 and maximum, the profile lines, the sutures' positions and forces, the line loads."""
    from ..physics.job import stress_summary
    from ..physics.profiles import locate_cells, profile_lines, sample_profiles, wound_edge_x

    m, d = sc.model, sc.domain
    vm = m.forms.von_mises_cells()
    samples = m.forms.von_mises_samples()  # None on P1: the cells are the samples
    stats = stress_summary(
        vm, d.volumes, d.cell_vertices, d.midpoints, samples,
        None if samples is None else d.X[d.cell_vertices],
        None if samples is None else m.forms.von_mises_vertices(), d.near_wound_cells(),
    )  # fmt: skip
    lines = profile_lines(d.X, wound_edge_x(d.points, d.facets, d.facet_tags))
    located = locate_cells(d, lines.reshape(-1, 3)).reshape(lines.shape[:2])
    loads = _line_loads(m) or (None, None, None)
    return ViewState(
        label, np.array(m.displacement_input(), float), np.asarray(vm, float)[np.argsort(d.cell_input)],
        float(stats["p99_von_mises_kPa"]), float(stats["max_von_mises_kPa"]), lines,
        sample_profiles(located, vm), np.asarray(sc.positions_mm, float),
        np.asarray(sc.suture_forces(), float), *loads,
    )  # fmt: skip


def case_view(sc: SuturedClosure, bite_width_mm: float, states: list[ViewState]) -> CaseView:
    """The mesh of ``sc`` with ``states`` (the bites at the first state's sutures)."""
    d = sc.domain
    ys = states[0].suture_y_mm if states else np.zeros(0)
    return CaseView(
        d.points, d.cells, d.cell_tags, d.facets, d.facet_tags, int(d.degree),
        bite_points(d, sc.lens, ys, bite_width_mm), wound_rim(d), states,
    )  # fmt: skip


def thread_arc(a: np.ndarray, b: np.ndarray, rise: float, n: int = _ARC_POINTS) -> np.ndarray:
    """(n, 3) a thread from ``a`` to ``b`` arching ``rise`` (mm) above their chord."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a + t * (b - a) + rise * np.sin(np.pi * t) * np.array([0.0, 0.0, 1.0])


class Line3D(NamedTuple):
    """A line of the view (`woundsweep.viz.view.LineTrace`'s fields)."""

    name: str
    points: np.ndarray  # (p, 3) reference, NaN rows between polylines
    displacement: np.ndarray  # (p, 3)
    color: str
    width: float
    group: str


def view_lines(view: CaseView, state: ViewState) -> list[Line3D]:
    """The wound's rim and one thread per suture at ``state`` (reference points and their
    displacement, so that the view's deformation scale moves them with the surface)."""
    p, u = view.points_mm, state.displacement_mm
    gap = np.full((len(view.rim), 1, 3), np.nan)
    rim_p = np.concatenate([p[view.rim], gap], axis=1).reshape(-1, 3)
    rim_u = np.concatenate([u[view.rim], np.zeros_like(gap)], axis=1).reshape(-1, 3)
    out = [Line3D("the wound's rim", rim_p, rim_u, "black", 5.0, "the wound's rim")]
    for i, (ia, ib) in enumerate(view.bites):
        a, b = p[ia] + u[ia], p[ib] + u[ib]
        rise = THREAD_RISE * float(np.linalg.norm(b - a))
        ref, moved = thread_arc(p[ia], p[ib], rise), thread_arc(a, b, rise)
        y, f = state.suture_y_mm[i], state.suture_force_mN[i]
        name = f"suture {i + 1} at y = {y:+.1f} mm: {f / 1000:.3g} N ({f:.0f} mN)"
        out.append(Line3D(name, ref, moved - ref, "#d62728", 7.0, "threads (sutures)"))
    return out


def view_png(surface: SurfacePatch, out: Path, title: str = "") -> str:
    """``view.png``: ``surface`` (the sutured skin around the wound) in 3D, shaded, coloured
    by its rise above the far field (mm; the dog-ears at the apices), the wound's rim in
    black and each suture's thread from bite to bite in red; heights exaggerated
    `VIEW_Z_SCALE` times."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import LightSource, Normalize
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator
    from mpl_toolkits.mplot3d.art3d import (  # type: ignore[import-untyped]
        Line3DCollection,
        Poly3DCollection,
    )

    sp = surface
    p, tri = sp.points, sp.triangles
    rise = sp.rise_mm[tri].mean(axis=1)
    norm = Normalize(min(float(rise.min()), 0.0), max(float(rise.max()), 1e-6))
    cmap = colormaps["viridis"]
    # Shading by the facets' normals as drawn (heights exaggerated), lit from the upper left.
    q = p * np.array([1.0, 1.0, VIEW_Z_SCALE])
    normal = np.cross(q[tri[:, 1]] - q[tri[:, 0]], q[tri[:, 2]] - q[tri[:, 0]])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    normal *= np.sign(normal[:, 2:3] + 1e-30)
    light = LightSource(azdeg=315, altdeg=50).shade_normals(normal, fraction=1.0)
    colour = cmap(norm(rise))
    colour[:, :3] *= (0.55 + 0.45 * light)[:, None]
    fig = Figure(figsize=(9, 6.5), layout="constrained")
    ax = fig.add_subplot(projection="3d", computed_zorder=False)
    ax.add_collection3d(
        Poly3DCollection(p[tri], facecolors=colour, edgecolors=(0, 0, 0, 0.06), linewidths=0.2,
                         zorder=1)
    )  # fmt: skip
    if len(sp.outline):
        ax.add_collection3d(
            Line3DCollection(sp.outline, colors="black", linewidths=1.6, zorder=3,
                             label="the wound's rim")
        )  # fmt: skip
    # The arcs rise THREAD_RISE of their span as drawn (heights exaggerated).
    arcs = [
        thread_arc(a, b, THREAD_RISE / VIEW_Z_SCALE * float(np.linalg.norm(b - a)))
        for a, b in sp.sutures
    ]
    for k, arc in enumerate(arcs):
        ax.plot(*arc.T, color="#d62728", lw=2.2, zorder=5, label="threads" if k == 0 else None)
        ax.plot(*arc[[0, -1]].T, ls="none", marker="o", ms=3, color="#7f0000", zorder=6)
    lo, hi = p.min(axis=0), p.max(axis=0)
    top = max([float(hi[2]), *(float(a[:, 2].max()) for a in arcs)])
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], top))
    span = hi - lo
    ax.set_box_aspect((span[0], span[1], VIEW_Z_SCALE * max(top - float(lo[2]), 1e-3)), zoom=1.25)
    ax.view_init(elev=32, azim=-58)
    for axis, n in ((ax.xaxis, 5), (ax.yaxis, 6), (ax.zaxis, 2)):
        axis.set_major_locator(MaxNLocator(n))
    ax.tick_params(labelsize=8, pad=0)
    ax.set_xlabel("x, across the wound (mm)", fontsize=9, labelpad=2)
    ax.set_ylabel("y, along the wound (mm)", fontsize=9, labelpad=4)
    ax.set_zlabel("z (mm)", fontsize=9, labelpad=6)
    sm = ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(
        sm, ax=ax, location="bottom", shrink=0.45, aspect=30, pad=0.0,
        label="colour: rise of the skin above the far field (mm)",
    )  # fmt: skip
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    ax.set_title(
        (title + "\n" if title else "")
        + f"sutured, deformed (true scale in x, y; heights x{VIEW_Z_SCALE:g})",
        fontsize=10,
    )
    atomic_write(out / "view.png", lambda tmp: fig.savefig(tmp, dpi=120, format="png"))
    return "view.png"
