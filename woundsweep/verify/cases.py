"""The verification cases: each a name, what it measures, the expected value with its
tolerance, whether it belongs to the quick subset, and the function that measures it.

`CASES` is the one registry `woundsweep verify` and `tests/verify` run. A case's ``run``
returns the measured value; `Case.judge` compares it with the expectation. Cases that share
a solve (the flat contact patch's four, an MMS study's L2 and H1 rates) share it through the
solving modules' caches, so each solve runs once per process.

Kinds of expectation: ``approx`` (|measured - expected| <= tolerance), ``at-most``
(measured <= expected + tolerance) and ``locking`` (an expected failure: P1 near
incompressibility, whose measured rate is printed as it is and passes while it stays below
the optimal rate by more than the tolerance, so the day P1 stops locking the case says so).

Closures: the stage-3 identity is the known answer of the `reactions` closure
(`StageSettings.closure_load`); `CLOSURE_CASES` maps each closing load to its cases, and a
closing load added to `config.paper.CLOSURE_LOADS` adds its known answers there.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import Any

from . import closures, contact_cases, objectivity, slit, threads
from .mms import MmsSeries, MmsSpec, run_series

__all__ = ["CASES", "CLOSURE_CASES", "Case", "Outcome", "mms_series", "select"]

KINDS = ("approx", "at-most", "locking")


@dataclasses.dataclass(frozen=True)
class Case:
    """One verification case; ``run()`` returns the measured value (``unit``)."""

    name: str
    what: str
    expected: float
    tolerance: float
    run: Callable[[], float]
    quick: bool = False
    kind: str = "approx"
    unit: str = ""

    def judge(self, measured: float) -> bool:
        """Whether ``measured`` meets the expectation."""
        if not math.isfinite(measured):
            return False
        if self.kind == "approx":
            return abs(measured - self.expected) <= self.tolerance
        if self.kind == "at-most":
            return measured <= self.expected + self.tolerance
        if self.kind == "locking":
            return measured < self.expected - self.tolerance
        raise ValueError(f"unknown kind {self.kind!r}")

    def expectation(self) -> str:
        """The expectation as the table prints it."""
        if self.kind == "at-most":
            return f"<= {self.expected:.3g}"
        if self.kind == "locking":
            return f"< {self.expected:.3g} (locks)"
        return f"{self.expected:.6g}"


@dataclasses.dataclass(frozen=True)
class Outcome:
    """A case's result: the measured value, whether it passed, its time, and the error
    message when it could not be measured."""

    case: Case
    measured: float
    passed: bool
    time_s: float
    error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        c = self.case
        return {
            "name": c.name, "what": c.what, "kind": c.kind, "unit": c.unit,
            "measured": self.measured if math.isfinite(self.measured) else None,
            "expected": c.expected, "tolerance": c.tolerance, "passed": self.passed,
            "quick": c.quick, "time_s": self.time_s, "error": self.error,
        }  # fmt: skip


# -- MMS --------------------------------------------------------------------------------------

P1_LEVELS, P2_LEVELS = (4, 6, 8, 12), (2, 3, 4, 6)
QUICK_P1, QUICK_P2 = (2, 4, 8), (2, 3, 4)
COMPRESSIBLE = {"fung": 10.0, "mooney-rivlin": 1.0}  # kPa: K / mu 1.7 (Fung), 1.25 (M-R)
NEAR_INCOMPRESSIBLE_K = 5000.0  # kPa, Mooney-Rivlin: K / mu = 6250
RATE_TOL = 0.25
_SERIES: dict[MmsSpec, MmsSeries] = {}


def mms_series(spec: MmsSpec) -> MmsSeries:
    """The study ``spec``, solved once per process."""
    if spec not in _SERIES:
        _SERIES[spec] = run_series(spec)
    return _SERIES[spec]


def _mms_cases() -> list[Case]:
    out: list[Case] = []
    studies = [
        ("fung-0", "fung", 0.0), ("fung-45", "fung", 45.0), ("mr", "mooney-rivlin", 0.0),
    ]  # fmt: skip
    quick = {("fung-45", 2, "K"), ("mr", 2, "paper"), ("mr", 1, "K")}
    for label, material, angle in studies:
        for degree in (2, 1):
            for moduli in ("K", "paper"):
                q = (label, degree, moduli) in quick
                levels = (QUICK_P2 if degree == 2 else QUICK_P1) if q else (
                    P2_LEVELS if degree == 2 else P1_LEVELS)  # fmt: skip
                K = COMPRESSIBLE[material] if moduli == "K" else None
                spec = MmsSpec(material, degree, levels, angle, K)
                name = f"mms-{label}-p{degree}-{'compressible' if K else 'paper'}"
                kr = f"K/mu {spec.bulk_to_shear():.3g}"
                for norm, order in (("l2", degree + 1), ("h1", degree)):
                    out.append(Case(
                        f"{name}-{norm}", f"MMS {norm.upper()} rate, {material} {angle:g} deg, "
                        f"P{degree}, {kr}, n = {', '.join(map(str, levels))}",
                        float(order), RATE_TOL, _rate(spec, norm), quick=q, unit="rate",
                    ))  # fmt: skip
    spec = MmsSpec("mooney-rivlin", 1, P1_LEVELS, 0.0, NEAR_INCOMPRESSIBLE_K)
    out.append(Case(
        "mms-mr-p1-near-incompressible-l2",
        f"MMS L2 rate, mooney-rivlin, P1, K/mu {spec.bulk_to_shear():.3g}: P1 locks",
        2.0, 0.5, _rate(spec, "l2"), kind="locking", unit="rate",
    ))  # fmt: skip
    return out


def _rate(spec: MmsSpec, norm: str) -> Callable[[], float]:
    def run() -> float:
        s = mms_series(spec)
        return s.l2_rate if norm == "l2" else s.h1_rate

    return run


# -- closures ---------------------------------------------------------------------------------


def _reactions_cases() -> list[Case]:
    return [
        Case("closure-reactions-stage3", "reactions closure: stage 3's state is stage 2's, "
             "max |u3 - u2| / max |u2|, P2 cylinder (demo job 0's)", 0.0, 1e-6,
             lambda: slit.stage3_identity(2)[0], quick=True, kind="at-most"),
    ]  # fmt: skip


def _paper_code_cases() -> list[Case]:
    return [
        Case("closure-paper-code-amplitude", "paper-code closure: amplitude at the homogeneous "
             "state over 1.3 x 1.4 P_xx of the dermis, P2 cylinder, 45 deg", 1.0, 1e-9,
             closures.code_amplitude_ratio, quick=True, unit="ratio"),
    ]  # fmt: skip


def _solved_cases() -> list[Case]:
    return [
        Case("closure-traction-area", "closing traction: a unit traction's pull on a flank over "
             "the zone's projected area, P2 cylinder", 1.0, 1e-9,
             closures.traction_area_ratio, quick=True, unit="ratio"),
        Case("closure-solved-gap", "solved closure: |median surface gap| / w after stage 3, P2 "
             "cylinder, 45 deg", 0.0, 1e-6, closures.solved_median_gap_per_w, kind="at-most"),
    ]  # fmt: skip


# closing load (`StageSettings.closure_load`) -> its known answers.
CLOSURE_CASES: dict[str, Callable[[], list[Case]]] = {
    "reactions": _reactions_cases,
    "paper-code": _paper_code_cases,
    "solved": _solved_cases,
}


def _slit_cases() -> list[Case]:
    def force(d: int) -> float:
        r = slit_closure(d)
        return r.force_per_length / r.expected_per_length

    def misfit(d: int) -> float:
        return slit_closure(d).misfit_off_pins

    out = []
    for d in (2, 1):
        out += [
            Case(f"slit-force-p{d}", f"slit closed over its whole length and depth, P{d}: "
                 "closing force per length over sum P_xx t (normal skin, 0 deg)",
                 1.0, 1e-6, functools.partial(force, d),
                 quick=True, unit="ratio"),
            Case(f"slit-homogeneous-p{d}", f"slit, P{d}: max |u - u_homogeneous| / ((TSF - 1) "
                 "L) off the gauge pins", 0.0, 1e-5,
                 functools.partial(misfit, d), quick=True, kind="at-most"),
        ]  # fmt: skip
    return out


@functools.cache
def _slit_threads() -> threads.SlitThreads:
    return threads.slit_threads(2, degree=1, grid=4)


def _thread_cases() -> list[Case]:
    def balance() -> float:
        r = _slit_threads()
        return (r.total_pull_mN + r.pin_transfer_mN) / r.expected_total_mN

    return [
        Case("slit-threads-force", "slit closed by 2 threads, P1: sum of 2 T (and what the gauge "
             "pins pass) over sum P_xx t L", 1.0, 1e-5, balance, unit="ratio"),
    ]  # fmt: skip


_SLIT: dict[int, slit.SlitResult] = {}


def slit_closure(degree: int) -> slit.SlitResult:
    if degree not in _SLIT:
        _SLIT[degree] = slit.slit_closure(degree)
    return _SLIT[degree]


# -- objectivity and contact ------------------------------------------------------------------


def _other_cases() -> list[Case]:
    fp = contact_cases.flat_patch
    return [
        Case("objectivity-residual", "R(Q (X + u) - X) = Q R(u) node by node, P2, both layers, "
             "Q 40 deg about (1, 2, 3): max error / max |R|", 0.0, 1e-10,
             objectivity.residual_objectivity, quick=True, kind="at-most"),
        Case("objectivity-solution", "problem turned 25 deg about z (mesh, boundary values, "
             "Langer line 20 -> 45 deg), P2: max |u' - Q u| / max |u|", 0.0, 1e-8,
             objectivity.solution_objectivity, quick=True, kind="at-most"),
        Case("contact-flat-force", "flat patch, p = 10 kPa: |contact force - p A| / (p A) at "
             "k_V = 1, 5, 100 GPa", 0.0, 0.01, lambda: fp().force_error, quick=True,
             kind="at-most"),
        Case("contact-flat-overlap", "flat patch: |overlap k_V / (p h) - 1| off the faces' "
             "edges, k_V = 1, 5, 100 GPa", 0.0, 0.01, lambda: fp().overlap_error, quick=True,
             kind="at-most"),
        Case("contact-penetration-slope", "flat patch: d log(max overlap) / d log k_V over "
             "1, 5, 100 GPa", -1.0, 0.02, lambda: fp().penetration_slope, quick=True),
        Case("contact-energy-monotone", "flat patch: largest drop of the equilibrium potential "
             "along the ramp 1 MPa -> 100 GPa, over |Pi|", 0.0, 1e-9,
             lambda: fp().energy_drop, quick=True, kind="at-most"),
        Case("contact-curved-pressure", "shrink fit of two tubes (curved master): interface "
             "pressure over Lame's plane-strain answer (16 to 32 segments: +9.4 % to +4.9 %)",
             1.0, 0.08,
             lambda: _shrink().pressure_kPa / _shrink().expected_kPa, unit="ratio"),
        Case("contact-curved-energy-monotone", "shrink fit: largest drop of the potential "
             "along the ramp 1 kPa -> 100 GPa, over |Pi|", 0.0, 1e-9,
             lambda: _shrink().energy_drop, kind="at-most"),
    ]  # fmt: skip


def _shrink() -> contact_cases.ShrinkFit:
    return contact_cases.shrink_fit(SHRINK_DEGREE, SHRINK_N_THETA)


SHRINK_DEGREE, SHRINK_N_THETA = 2, 32  # 4 elements across each tube


def all_cases() -> list[Case]:
    """Every case, in the table's order."""
    cases = _mms_cases() + _slit_cases() + _thread_cases()
    for make in CLOSURE_CASES.values():
        cases += make()
    return cases + _other_cases()


CASES: tuple[Case, ...] = tuple(all_cases())


def select(quick: bool, names: tuple[str, ...] = ()) -> list[Case]:
    """The cases to run: those named (a name selects every case it prefixes), else the
    quick subset or all. Raises KeyError naming an unknown name."""
    if names:
        chosen = [c for c in CASES if any(c.name.startswith(n) for n in names)]
        unknown = [n for n in names if not any(c.name.startswith(n) for c in CASES)]
        if unknown:
            raise KeyError(", ".join(unknown))
        return chosen
    return [c for c in CASES if c.quick or not quick]
