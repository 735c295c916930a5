"""Running the cases and reporting them: the table, the JSON record and the convergence
plots of the MMS studies (matplotlib, Agg)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from .cases import Case, Outcome, mms_series
from .mms import MmsSeries

__all__ = ["plot_studies", "run_cases", "table", "to_json"]


def run_cases(cases: Sequence[Case], progress: Callable[[Outcome], None] | None = None
              ) -> list[Outcome]:  # fmt: skip
    """Run each case once; a case whose solve fails is a failed outcome with its message."""
    out = []
    for case in cases:
        t0 = time.perf_counter()
        error = None
        try:
            measured = float(case.run())
        except (ArithmeticError, RuntimeError, ValueError) as exc:
            measured, error = math.nan, f"{type(exc).__name__}: {exc}"
        o = Outcome(case, measured, error is None and case.judge(measured),
                    time.perf_counter() - t0, error)  # fmt: skip
        out.append(o)
        if progress is not None:
            progress(o)
    return out


def _num(v: float, tol: float = 1.0) -> str:
    if not math.isfinite(v):
        return "-"
    if abs(v) >= 1e-3 or v == 0:
        return f"{v:.10g}" if tol < 1e-4 else f"{v:.4g}"
    return f"{v:.2e}"


def row(o: Outcome) -> str:
    """One line of the table."""
    c = o.case
    status = ("locking" if o.passed else "NOT LOCKING") if c.kind == "locking" else (
        "pass" if o.passed else "FAIL")  # fmt: skip
    tol = f"{c.tolerance:.2g}"
    line = (f"{c.name:<40} {_num(o.measured, c.tolerance):>12} {c.expectation():>16} {tol:>8} "
            f"{status:<7} {o.time_s:6.1f}")  # fmt: skip
    return line + (f"  {o.error}" if o.error else "")


def table(outcomes: Sequence[Outcome]) -> list[str]:
    """The printed table: case, measured, expected, tolerance, pass, time (s)."""
    head = (f"{'case':<40} {'measured':>12} {'expected':>16} {'tol':>8} {'result':<7} "
            f"{'time s':>6}")  # fmt: skip
    return [head] + [row(o) for o in outcomes]


def to_json(outcomes: Sequence[Outcome], total_s: float, dolfinx: str) -> str:
    return json.dumps({
        "passed": all(o.passed for o in outcomes), "failed": [o.case.name for o in outcomes
        if not o.passed], "dolfinx_version": dolfinx, "time_s": total_s,
        "cases": [o.to_dict() for o in outcomes], "mms": [_series_dict(s) for s in studies()],
    }, indent=1)  # fmt: skip


def studies() -> list[MmsSeries]:
    """The MMS studies solved in this process."""
    from .cases import _SERIES

    return list(_SERIES.values())


def _series_dict(s: MmsSeries) -> dict[str, Any]:
    sp = s.spec
    return {
        "material": sp.material, "angle_deg": sp.angle_deg, "degree": sp.degree,
        "K_kPa": sp.job_materials().dermis.K if sp.material == "fung"
        else sp.job_materials().subcutis.K, "K_over_mu": sp.bulk_to_shear(),
        "n": list(sp.levels), "h": s.h, "dofs": s.dofs, "l2_error_mm": s.l2,
        "h1_error": s.h1, "newton_steps": s.newton_steps, "l2_rate": s.l2_rate,
        "h1_rate": s.h1_rate, "time_s": s.time_s,
    }  # fmt: skip


def rates_table() -> list[str]:
    """The MMS rates, one line per study."""
    lines = [f"{'material':<14} {'angle':>5} {'P':>2} {'K/mu':>7} {'n':<12} {'L2 rate':>8} "
             f"{'H1 rate':>8} {'L2 error (finest)':>18}"]  # fmt: skip
    for s in studies():
        sp = s.spec
        lines.append(
            f"{sp.material:<14} {sp.angle_deg:>5g} {sp.degree:>2} {sp.bulk_to_shear():>7.3g} "
            f"{','.join(map(str, sp.levels)):<12} {s.l2_rate:>8.2f} {s.h1_rate:>8.2f} "
            f"{s.l2[-1]:>18.3e}"
        )
    return lines


def plot_studies(out: Path) -> list[Path]:
    """One PNG per MMS study in ``out``: L2 and H1 errors against h with their fitted
    slopes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    written = []
    for s in studies():
        sp = s.spec
        fig, ax = plt.subplots(figsize=(4.5, 3.5))
        for errs, rate, label in ((s.l2, s.l2_rate, "L2"), (s.h1, s.h1_rate, "H1 seminorm")):
            ax.loglog(s.h, errs, "o-", label=f"{label}: rate {rate:.2f}")
        ax.set_xlabel("h (mm)")
        ax.set_ylabel("error")
        K = f"K/mu {sp.bulk_to_shear():.3g}"
        ax.set_title(f"MMS {sp.material} {sp.angle_deg:g} deg, P{sp.degree}, {K}", fontsize=9)
        ax.legend(fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        name = f"mms-{sp.material}-{sp.angle_deg:g}-p{sp.degree}-K{sp.bulk_to_shear():.3g}.png"
        path = out / name
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


__all__ += ["mms_series", "rates_table", "row", "studies"]
