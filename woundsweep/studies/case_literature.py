"""What the literature reports beside a case's numbers (`woundsweep case`, the report's
"Against the literature"), each figure with its source, and the forces at which a suture in
skin fails (the margin of the report's bottom line).

The model's side of the comparison is computed, not quoted: the forces of the solve, the
dermis's pre-stress from Table 2's pre-stretch (`homogeneous_state`), its small-strain
stiffness along the Langer line (2 mu1 + lambda11) and how much its Fung law stiffens at a
20 % stretch (exp(Q), Q = (2 mu1 + lambda11) E^2 / c).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from .case import CaseResult

__all__ = [
    "BREAKING",
    "REPORTED",
    "REPORTED_RANGE_N",
    "SKIN_EX_VIVO",
    "SMALLEST_REPORTED_PEAK_N",
    "TEAR_THROUGH",
    "Failure",
    "Ours",
    "Reported",
    "SkinModel",
    "literature_section",
    "ours",
    "skin_model",
]


class Failure(NamedTuple):
    """A way a suture fails, its force range (N) and the source."""

    low_N: float
    high_N: float
    text: str


# The smallest failure force: a suture tearing through the skin, not the thread breaking.
TEAR_THROUGH = Failure(
    3.44,
    4.04,
    "4-0 nylon tears through a skin model at 3.8 N (3.4 N for 5-0, 4.0 N for 3-0; Potter et "
    "al., Dermatol. Surg. 2025;51(2):148, reverse cutting needle, artificial skin)",
)
BREAKING = Failure(
    18.9,
    30.9,
    "a nylon thread breaks far above that: 3-0 nylon at 30.9 N pulled straight, and no knotted "
    "3-0 non-absorbable suture above 18.9 N (Naleway et al., J. Biomed. Mater. Res. B "
    "2015;103:735); 4-0 is thinner (USP diameter 0.150-0.199 mm against 0.200-0.249 mm) and "
    "breaks lower, still several times above the tear-through force",
)


class Reported(NamedTuple):
    """Suture forces a study reports."""

    source: str
    method: str
    wound_mm: str
    force_N: str
    centre_to_end: str


REPORTED = (
    Reported(
        "Capek et al., Med. Biol. Eng. Comput. 2012;50:193",
        "FE of elliptical wounds, the study's highest pre-stress (largest force per wound)",
        "30 x 5 to 30 x 15", "0.5-1.5", "largest in the middle",
    ),
    Reported(
        "Capek et al. 2012", "measured in vivo (peak force per wound)",
        "36 x 5 to 46 x 13", "1.1-3.2", "",
    ),
    Reported(
        "Wen et al., Appl. Math. Mech. 2023;44:441",
        "FE and a neural-network surrogate, validated on pig skin (peak force)",
        "40 x 10, 40 x 14", "1.7, 2.5 (+-0.6)", "",
    ),
    Reported(
        "Chanda and Unnikrishnan", "3D two-layer skin FE, interrupted sutures",
        "centimetre-size", "0-5", "about 4",
    ),
)  # fmt: skip
# The span of all of these: about 0.1 N (end sutures of small wounds) to 5 N; the smallest
# peak force among them (Capek et al.'s 30 x 5 mm wound).
REPORTED_RANGE_N = (0.1, 5.0)
SMALLEST_REPORTED_PEAK_N = 0.5
# Excised back skin in uniaxial tension (Ni Annaidh et al., J. Mech. Behav. Biomed. Mater.
# 2012;5:139): the initial slope and the modulus of the linear part (MPa).
SKIN_EX_VIVO = {"initial slope": 1.18, "linear modulus": 83.3}
_STRETCH = 1.2


class SkinModel(NamedTuple):
    """Table 2's dermis of one skin type, as the comparison needs it (kPa)."""

    skin_type: str
    prestress_along_kPa: float  # P along the Langer line at the pre-stretch
    prestress_across_kPa: float
    stiffness_kPa: float  # 2 mu1 + lambda11
    stiffening: float  # exp(Q) at a 20 % stretch along the line


def skin_model(skin_type: str) -> SkinModel:
    """`SkinModel` of ``skin_type`` (numpy; no solve)."""
    from ..config.paper import FungParameters
    from ..physics.materials import JobMaterials, homogeneous_state

    p: FungParameters = getattr(FungParameters, skin_type)()
    m = JobMaterials.table2(skin_type, 90.0)  # the Langer line along y
    P = homogeneous_state(m.dermis, m.tsf).P
    k = 2 * p.mu_kPa[0] + p.lambda11_kPa
    E = 0.5 * (_STRETCH**2 - 1)
    return SkinModel(skin_type, float(P[1, 1]), float(P[0, 0]), k, math.exp(k * E * E / p.c_kPa))


class Ours(NamedTuple):
    """The case's side of the comparison (N)."""

    peak_N: float
    smallest_N: float
    band_peak_N: tuple[float, float] | None  # the peak force at the band's ends
    centre_to_end: float | None  # the largest force over the mean of the end sutures'
    below_reported: float  # how many times the peak is below the smallest reported peak


def ours(result: CaseResult) -> Ours:
    """The case's numbers for the comparison, from its solved forces."""
    f = result.sutured.suture_force_mN / 1e3
    ends = [b.sutured.suture_force_mN.max() / 1e3 for b in result.band]
    band = (min([*ends, f.max()]), max([*ends, f.max()])) if ends else None
    ratio = float(f.max() / np.mean([f[0], f[-1]])) if len(f) >= 3 else None
    return Ours(
        float(f.max()), float(f.min()), band, ratio, SMALLEST_REPORTED_PEAK_N / float(f.max())
    )


def _n(f_N: float) -> str:
    return f"{f_N:.3g} N"


def _shape(result: CaseResult) -> str:
    """Whether the forces peak inside the wound and are smallest at its ends, as reported."""
    f = result.sutured.suture_force_mN
    if len(f) < 3:
        return ""
    inside = 0 < int(np.argmax(f)) < len(f) - 1 and min(f[0], f[-1]) <= f.min() * (1 + 1e-6)
    if inside:
        return "The shape agrees: the largest forces are inside the wound, the end sutures carry least. "
    return "Unlike the reports, the largest force is not inside the wound here. "


def literature_section(result: CaseResult) -> list[str]:
    """The report's "Against the literature" lines: the reported forces beside the case's
    (`ours`) and the reasons for the gap, with the model's numbers (`skin_model`)."""
    c = result.case
    o = ours(result)
    band = (
        f" (largest {o.band_peak_N[0]:.3g}-{o.band_peak_N[1]:.3g}, {' to '.join(c.band)} skin)"
        if o.band_peak_N
        else ""
    )
    ratio = f"{o.centre_to_end:.1f}" if o.centre_to_end is not None else "n/a (fewer than 3)"
    lines = [
        "| | method | wound (mm) | force (N) | largest / end suture |",
        "|---|---|---|---|---|",
        f"| this case | FE, held footprints (apposition force) | {c.length_mm:g} x {c.width:.3g} "
        f"| {o.smallest_N:.3g}-{o.peak_N:.3g}{band} | {ratio} |",
    ]
    if result.threads is not None:
        T = result.threads.sutured.suture_force_mN / 1e3
        ends = (T[0] + T[-1]) / 2
        tr_ratio = f"{T.max() / ends:.1f}" if len(T) >= 3 else "n/a (fewer than 3)"
        lines.append(
            f"| this case | FE, threads drawn until the walls meet (tension) "
            f"| {c.length_mm:g} x {c.width:.3g} | {T.min():.3g}-{T.max():.3g} | {tr_ratio} |"
        )
    lines += [
        f"| {r.source} | {r.method} | {r.wound_mm} | {r.force_N} | {r.centre_to_end} |"
        for r in REPORTED
    ]
    lo, hi = REPORTED_RANGE_N
    names = dict.fromkeys((*c.band, c.skin_type))  # the band and the case's skin, once each
    skins = sorted((skin_model(s) for s in names), key=lambda s: s.stiffness_kPa)
    pre = [p for s in skins for p in (s.prestress_across_kPa, s.prestress_along_kPa)]
    stiff = [s.stiffness_kPa for s in skins]
    grow = [s.stiffening for s in skins]
    lines += [
        "",
        f"The largest force here, {_n(o.peak_N)}, is {o.below_reported:.1f} times below the "
        f"smallest peak force reported ({SMALLEST_REPORTED_PEAK_N:g} N, a 30 x 5 mm ellipse), "
        f"and reported forces span about {lo:g}-{hi:g} N. {_shape(result)}The gap has these "
        "reasons:",
        "",
        "- **What is measured.** Here a suture is the hold of the edges over its footprint, and "
        "its force is what holds them together there (the apposition force). A thread pulls "
        "at its bites, a bite width from the edge, so its tension also carries the tissue "
        "between bite and edge and whatever tightening the surgeon adds; the studies above "
        "report thread or pulling forces.",
        f"- **Pre-stress.** Table 2's pre-stretch (Flynn et al.'s facial skin) leaves the dermis "
        f"under {min(pre):.1f}-{max(pre):.1f} kPa before the cut (across to along the Langer "
        "line, soft to stiff skin); the closing force scales with it, and Capek et al.'s "
        "forces are those of their highest pre-stress.",
        f"- **Stiffness.** Table 2's dermis has a small-strain stiffness along the line "
        f"(2 mu1 + lambda11) of {min(stiff):.0f}-{max(stiff):.0f} kPa; excised back skin starts "
        f"at {SKIN_EX_VIVO['initial slope']:g} MPa and reaches {SKIN_EX_VIVO['linear modulus']:g} "
        "MPa once its collagen is recruited (Ni Annaidh et al., J. Mech. Behav. Biomed. Mater. "
        "2012;5:139).",
        f"- **Stiffening.** At a {100 * (_STRETCH - 1):.0f} % stretch along the line, Table 2's "
        f"Fung law is only {100 * (min(grow) - 1):.0f}-{100 * (max(grow) - 1):.0f} % stiffer than "
        "at rest (exp(Q)); skin stiffens by orders of magnitude over the same range.",
        "",
        "So the forces here rank sutures, placements and directions of one wound against each "
        "other; their size in newtons is a lower bound, not a prediction of thread tension.",
    ]
    return lines
