"""The figures of a case's report (`woundsweep case`), besides ``view.png``
(`case_report`):

- ``forces.png``: each suture's force at its own position along the wound: as placed (with
  the site's band of skin types), under the load after closure, at the evened placement and
  along the Langer line (`force_series`, the data drawn);
- ``wound.png``: along the wound, the surface gap (as sutured and at each step of the load,
  with the "open" threshold), the contact pressure and the surface von Mises beside the edge,
  the sutures marked.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..config.case import OPEN_GAP_mm
from ..core.fsutil import atomic_write
from .case import ITCH_STEPS, CaseResult, best_evened

__all__ = ["Series", "force_series", "forces_png", "wound_png"]


class Series(NamedTuple):
    """One set of suture forces as drawn: positions y (mm), forces and their band (mN)."""

    label: str
    y_mm: np.ndarray
    force_mN: np.ndarray
    low_mN: np.ndarray | None = None
    high_mN: np.ndarray | None = None


def force_series(result: CaseResult) -> list[Series]:
    """The forces drawn in ``forces.png``, each at the positions of its own placement."""
    st = result.sutured
    low = high = None
    if result.band:
        stack = np.stack([st.suture_force_mN] + [b.sutured.suture_force_mN for b in result.band])
        low, high = stack.min(axis=0), stack.max(axis=0)
    out = [Series("as placed", st.suture_y_mm, st.suture_force_mN, low, high)]
    last = result.loaded.last
    if last is not None:
        deg = result.loaded.to_wound_deg
        out.append(Series(f"under the load ({deg:g} deg to the wound)", last.suture_y_mm,
                          last.suture_force_mN))  # fmt: skip
    best = best_evened(result)
    if best is not None:
        out.append(Series("evened placement", best.suture_y_mm, best.suture_force_mN))
    if result.along is not None:
        al = result.along
        out.append(Series("along the Langer line", al.suture_y_mm, al.suture_force_mN))
    return out


def forces_png(result: CaseResult, out: Path) -> str:
    """Write ``forces.png`` (module docstring); its name."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4), layout="constrained")
    ax = fig.subplots()
    for k, s in enumerate(force_series(result)):
        marker = "os^v"[k % 4]
        if s.low_mN is not None and s.high_mN is not None:
            err = np.stack([s.force_mN - s.low_mN, s.high_mN - s.force_mN]) / 1e3
            label = f"{s.label} (bars: {' to '.join(result.case.band)} skin)"
            ax.errorbar(s.y_mm, s.force_mN / 1e3, yerr=err, capsize=3, marker=marker, lw=1.0,
                        ms=5, label=label)  # fmt: skip
        else:
            ax.plot(s.y_mm, s.force_mN / 1e3, marker=marker, lw=1.0, ms=5, label=s.label)
    half = result.case.length_mm / 2
    ax.set_xlim(-half, half)
    ax.set_xlabel("y: position along the wound from its centre (mm)")
    ax.set_ylabel("force holding the edges at each suture (N)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    atomic_write(out / "forces.png", lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    return "forces.png"


def wound_png(result: CaseResult, out: Path) -> str:
    """Write ``wound.png`` (module docstring); its name."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    st = result.sutured
    last = result.loaded.last
    fig = Figure(figsize=(7, 8), layout="constrained")
    a1, a2, a3 = fig.subplots(3, 1, sharex=True)
    a1.plot(st.gap_y_mm, st.gap_mm, "k.-", label="sutured")
    for j, step in enumerate(result.itch, 1):
        if step.state is not None:
            a1.plot(
                step.state.gap_y_mm, step.state.gap_mm, ".-", lw=0.8, label=f"load {j}/{ITCH_STEPS}"
            )
    a1.axhline(OPEN_GAP_mm, color="r", ls=":", lw=0.8, label=f"open above {OPEN_GAP_mm:g} mm")
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
    a3.set_xlabel("y: position along the wound from its centre (mm)")
    a3.legend(fontsize=7)
    for ax in (a1, a2, a3):
        for y in st.suture_y_mm:
            ax.axvline(y, color="0.8", lw=0.6, zorder=0)
    atomic_write(out / "wound.png", lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    return "wound.png"
