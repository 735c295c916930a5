"""Physical and numerical ranges of a sweep's settings, checked when the sweep loads.

The type of every value is checked by `woundsweep.config.sweep` against the defaults; this
module bounds the values: a modulus within `MODULUS_DECADES` decades of Table 2's value for
its key (so K = 1e300 or c = 1e-300 never reaches the solver), the pre-stretch ``tsf`` in
`TSF_RANGE`, contact penalties increasing within `PENALTY_RANGE_GPA`, Newton's counts and
tolerances in `NEWTON_RANGES`, the quadrature degree up to `max_quadrature_degree`, and the
analysis settings as `ModelSettings.check` bounds them (so `generate` refuses what `analyze`
would). A value outside its range is a `SweepError` naming the key path.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..core.errors import AnalysisError, SweepError
from .analysis import ModelSettings
from .paper import FungParameters, Materials

__all__ = [
    "MODULUS_DECADES",
    "NEWTON_RANGES",
    "PENALTY_RANGE_GPA",
    "TSF_RANGE",
    "check_settings",
    "max_quadrature_degree",
]

MODULUS_DECADES = 3
TSF_RANGE = (1.0, 1.5)  # the paper's 1.05-1.15; below 1 the skin would be pre-compressed
PENALTY_RANGE_GPA = (1e-3, 1e4)
# key -> (lowest, highest), both allowed; counts are integers, the rest positive floats.
NEWTON_RANGES: Mapping[str, tuple[float, float]] = {
    "max_iterations": (1, 10_000),
    "max_stage_iterations": (1, 1_000_000),
    "load_steps": (1, 10_000),
    "max_load_cuts": (0, 40),
    "rtol": (1e-15, 0.5),
    "path_rtol": (1e-15, 0.5),
    "atol": (1e-300, 1e3),
    "stol": (1e-15, 0.5),
    "max_strain_step": (1e-6, 100.0),
    "gamma_min": (1e-12, 1.0),
    "residual_growth": (1.0, 1e12),
    "divergence_factor": (1.0, 1e100),
}


def max_quadrature_degree(element_degree: int) -> int:
    """The largest quadrature degree accepted: twice the element's, plus two (beyond it the
    cost grows without a gain in accuracy the stresses could show)."""
    return 2 * element_degree + 2


def _modulus(path: str, key: str, value: float, reference: float) -> None:
    lo, hi = reference / 10**MODULUS_DECADES, reference * 10**MODULUS_DECADES
    if not lo <= value <= hi:
        raise SweepError(
            path, key, f"expected a modulus within {MODULUS_DECADES} decades of Table 2's "
            f"{reference:g} kPa ({lo:.3g} to {hi:.3g}), got {value!r}",
        )  # fmt: skip


def _materials(path: str, materials: Mapping[str, Any]) -> None:
    table2 = Materials.table2()
    sub = table2.subcutis
    for key, value in materials["subcutis"].items():
        _modulus(path, f"materials.subcutis.{key}", value, getattr(sub, key))
    for name, params in materials["skin_types"].items():
        ref: FungParameters = table2.skin_types.get(name, table2.skin_types["normal"])
        where = f"materials.skin_types.{name}"
        for key, value in params.items():
            if key == "tsf":
                lo, hi = TSF_RANGE
                if not lo <= value <= hi:
                    raise SweepError(
                        path, f"{where}.tsf",
                        f"expected a pre-stretch in [{lo:g}, {hi:g}], got {value!r}",
                    )  # fmt: skip
            elif key == "mu_kPa":
                for i, (v, r) in enumerate(zip(value, ref.mu_kPa)):
                    _modulus(path, f"{where}.mu_kPa[{i}]", v, r)
            else:
                _modulus(path, f"{where}.{key}", value, getattr(ref, key))


def _stages(path: str, stages: Mapping[str, Any]) -> None:
    penalties = stages["contact_penalty_GPa"]
    lo, hi = PENALTY_RANGE_GPA
    for i, k in enumerate(penalties):
        if not lo <= k <= hi:
            raise SweepError(
                path, f"stages.contact_penalty_GPa[{i}]",
                f"expected a penalty in [{lo:g}, {hi:g}] GPa, got {k!r}",
            )  # fmt: skip
    if any(b <= a for a, b in zip(penalties, penalties[1:])):
        raise SweepError(
            path, "stages.contact_penalty_GPa", f"expected increasing penalties, got {penalties}"
        )


def _solver(path: str, solver: Mapping[str, Any]) -> None:
    for key, (lo, hi) in NEWTON_RANGES.items():
        value = solver[key]
        if not lo <= value <= hi:
            raise SweepError(path, f"solver.{key}", f"expected {lo:g} to {hi:g}, got {value!r}")
    q, top = solver["quadrature_degree"], max_quadrature_degree(solver["element_degree"])
    if not 1 <= q <= top:
        raise SweepError(
            path, "solver.quadrature_degree",
            f"expected 1 to {top} for element degree {solver['element_degree']}, got {q!r}",
        )  # fmt: skip


def check_settings(path: str, settings: Mapping[str, Any]) -> ModelSettings:
    """Bound the merged settings sections (plain form); returns the checked analysis settings."""
    _materials(path, settings["materials"])
    _stages(path, settings["stages"])
    _solver(path, settings["solver"])
    try:
        return ModelSettings(**settings["analysis"]).check()
    except AnalysisError as err:
        key, _, problem = str(err).partition(": ")
        raise SweepError(path, key, problem) from None
