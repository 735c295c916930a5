"""Number and position formats of a case's report (`woundsweep case`): forces in N with mN in
brackets, positions y along the wound in mm, stretches of the wound."""

from __future__ import annotations

import numpy as np

from .case_verdict import Stretch

__all__ = ["and_list", "newtons", "spread", "where", "y_mm", "ys_mm"]


def newtons(f_mN: float) -> str:
    """A force in N with mN in brackets."""
    return f"{f_mN / 1e3:.3g} N ({f_mN:.0f} mN)"


def y_mm(v: float) -> str:
    return f"{float(np.round(v, 1)) + 0.0:+.1f}"  # + 0.0: no "-0.0" at the centre


def and_list(ys: np.ndarray) -> str:
    """Positions as ``a, b and c``."""
    parts = [y_mm(y) for y in ys]
    return parts[0] if len(parts) == 1 else f"{', '.join(parts[:-1])} and {parts[-1]}"


def ys_mm(ys: np.ndarray) -> str:
    return ", ".join(y_mm(y) for y in ys)


def where(stretches: list[Stretch]) -> str:
    """``y = a to b mm and c to d mm (gap up to g mm)``."""
    parts = [
        f"{y_mm(s.y0_mm)}"
        if abs(s.y1_mm - s.y0_mm) < 0.05
        else f"{y_mm(s.y0_mm)} to {y_mm(s.y1_mm)}"
        for s in stretches
    ]
    gap = max(s.gap_max_mm for s in stretches)
    return f"y = {' and '.join(parts)} mm (gap up to {gap:.2f} mm)"


def spread(f: np.ndarray) -> float:
    return float(f.max() / max(f.min(), 1e-9))
