"""Grid convergence math (`woundsweep.studies.gci`) on analytic sequences; no DOLFINx."""

from __future__ import annotations

import math

import pytest

from woundsweep.core.errors import WoundsweepError
from woundsweep.studies.convergence import QUANTITIES, level_factors, parse_factors
from woundsweep.studies.gci import SAFETY_FACTOR, fit_study, grid_studies, grid_study


def sequence(f0: float, C: float, p: float, h1: float, r: float, n: int) -> list[float]:
    """f(h) = f0 + C h^p on h = h1 r^(n-1), ..., h1 r, h1 (coarse to fine)."""
    return [f0 + C * (h1 * r**k) ** p for k in reversed(range(n))]


@pytest.mark.parametrize(
    ("f0", "C", "p", "r"),
    [(30.0, 4.0, 2.0, 1.31), (30.0, -4.0, 1.0, 1.5), (-2.0, 0.7, 1.37, 2.0), (5.0, 1e-3, 0.5, 1.2)],
)
def test_analytic_sequence_gives_its_order_limit_and_error(f0, C, p, r) -> None:
    f3, f2, f1 = sequence(f0, C, p, 0.2, r, 3)
    s = grid_study(f1, f2, f3, r)
    assert s.kind == "monotone"
    assert s.ratio == pytest.approx(r**-p, rel=1e-9)
    assert s.order == pytest.approx(p, rel=1e-9)
    assert s.extrapolated == pytest.approx(f0, rel=1e-9, abs=1e-12)
    # On an exact power law the GCI is Fs times the true relative error of the finest grid.
    assert s.gci_fine == pytest.approx(SAFETY_FACTOR * abs((f1 - f0) / f1), rel=1e-8)


def test_triples_of_a_longer_sequence_each_recover_the_law() -> None:
    values = sequence(10.0, 3.0, 1.6, 0.1, 1.4, 5)
    studies = grid_studies(values, 1.4)
    assert len(studies) == 3
    for s in studies:
        assert s.order == pytest.approx(1.6, rel=1e-9) and s.extrapolated == pytest.approx(10.0)
    # The finest triple has the smallest GCI (the error shrinks with h).
    assert studies[-1].gci_fine < studies[0].gci_fine


def test_order_is_the_documented_formula() -> None:
    f1, f2, f3, r = 20.0, 20.9, 23.0, 1.31
    p = math.log((f3 - f2) / (f2 - f1)) / math.log(r)
    s = grid_study(f1, f2, f3, r)
    assert s.order == pytest.approx(p, rel=1e-12)
    assert s.extrapolated == pytest.approx(f1 + (f1 - f2) / (r**p - 1), rel=1e-12)


@pytest.mark.parametrize(
    ("values", "kind"),
    [
        ((36.2, 46.6, 34.0), "oscillatory"),  # a stage-3 p99 that oscillates, coarse to fine
        ((1.0, 2.0, 4.0), "divergent"),  # differences grow with refinement
        ((3.0, 3.0, 4.0), "divergent"),  # e32 = 0, e21 != 0
        ((5.0, 5.0, 5.0), "constant"),
        ((5.0, math.nan, 5.0), "undefined"),
    ],
)
def test_non_monotone_sequences_have_no_order(values, kind: str) -> None:
    f3, f2, f1 = values
    s = grid_study(f1, f2, f3, 1.3)
    assert s.kind == kind
    assert math.isnan(s.order)
    if kind == "constant":
        assert s.extrapolated == 5.0 and s.gci_fine == 0.0
    else:
        assert math.isnan(s.extrapolated) and math.isnan(s.gci_fine)


def test_ratio_must_exceed_one() -> None:
    with pytest.raises(ValueError, match="exceed 1"):
        grid_study(1.0, 2.0, 3.0, 1.0)
    with pytest.raises(ValueError, match="exceed 1"):
        grid_study(1.0, 2.0, 3.0, 1.5, 0.9)


def size_law(m: float) -> float:
    return (0.5 / m) ** (1 / 3)


@pytest.mark.parametrize(("f0", "C", "p"), [(18.0, 9.0, 1.0), (6.0, -0.8, 2.0), (20.0, 3.0, 0.55)])
def test_unequal_ratios_recover_a_power_law(f0, C, p) -> None:
    # The paper's factors and two finer levels: ratios 1.19, 1.12, 1.13, 1.12.
    h = [size_law(m) for m in (0.3, 0.5, 0.7, 1.0, 1.4)]
    values = [f0 + C * x**p for x in h]
    for s in grid_studies(values, h):
        assert s.kind == "monotone"
        assert s.order == pytest.approx(p, rel=1e-9)
        assert s.extrapolated == pytest.approx(f0, rel=1e-9)
    f3, f2, f1 = values[-3:]
    s = grid_studies(values, h)[-1]
    assert s.gci_fine == pytest.approx(SAFETY_FACTOR * abs((f1 - f0) / f1), rel=1e-8)


def test_unequal_ratios_divergence_is_against_the_zero_order_limit() -> None:
    # With r21 != r32 equal differences are not the boundary: p -> 0 gives
    # e32 / e21 -> ln r32 / ln r21, and any smaller growth has no positive order.
    r21, r32 = 1.25, 1.6
    limit = math.log(r32) / math.log(r21)
    assert grid_study(10.0, 11.0, 11.0 + 1.01 * limit, r21, r32).kind == "monotone"
    assert grid_study(10.0, 11.0, 11.0 + 0.99 * limit, r21, r32).kind == "divergent"
    # Equal ratios keep the closed form.
    assert grid_studies([13.0, 11.0, 10.0], [1.44, 1.2, 1.0])[0].order == pytest.approx(
        math.log(2.0) / math.log(1.2), rel=1e-12
    )


def test_element_sizes_must_match_the_values() -> None:
    with pytest.raises(ValueError, match="3 values but 2"):
        grid_studies([1.0, 2.0, 3.0], [2.0, 1.0])


def test_parse_factors() -> None:
    assert parse_factors("0.3,0.5,0.7,1,1.4") == [0.3, 0.5, 0.7, 1.0, 1.4]
    for text, msg in [("0.3,0.5", "at least 3"), ("0.3,x,1", "numbers"),
                      ("0.3,0.7,0.5", "increase"), ("0.3,0.7,8.5", "in \\(0, 8\\]"),
                      ("0,0.5,1", "in \\(0, 8\\]")]:  # fmt: skip
        with pytest.raises(WoundsweepError, match=msg) as exc:
            parse_factors(text)
        assert exc.value.exit_code == 2 and "\n" not in str(exc.value)


def test_level_factors() -> None:
    assert level_factors(0.3, 3, 1.5) == pytest.approx([0.3, 0.45, 0.675])
    assert level_factors(0.4, 3, 1.58113883)[-1] == pytest.approx(1.0)
    assert level_factors(0.5, 3, 2.0)[-1] == pytest.approx(2.0)
    for args, text in [((0.3, 2, 1.5), "expected 3"), ((0.3, 3, 1.0), "at least 1.05"),
                       ((0.3, 3, 1.0000000000000002), "at least 1.05"),
                       ((0.3, 11, 1.05), "to 10"), ((0.3, 5000, 1.5), "to 10"),
                       ((0.01, 10, 3.0), "passes 8"), ((0.5, 5, 2.1), "reach 9.72 > 8")]:  # fmt: skip
        with pytest.raises(WoundsweepError, match=text) as exc:
            level_factors(*args)
        assert exc.value.exit_code == 2 and "\n" not in str(exc.value)


PAPER_AND_FINER = (0.3, 0.4, 0.5, 0.6, 0.7, 1.0, 1.4, 2.0)


@pytest.mark.parametrize(("f0", "C", "p"), [(18.0, 9.0, 1.0), (6.0, -0.8, 2.0), (20.0, 3.0, 0.55)])
def test_fit_recovers_a_power_law_on_unequal_ratios(f0, C, p) -> None:
    h = [size_law(m) for m in PAPER_AND_FINER]
    s = fit_study([f0 + C * x**p for x in h], h)
    assert (s.kind, s.fit, s.safety_factor, s.scattered) == ("monotone", "power", 1.25, False)
    assert s.order == pytest.approx(p, rel=1e-6)
    assert s.extrapolated == pytest.approx(f0, rel=1e-8)
    assert s.sigma == pytest.approx(0.0, abs=1e-8 * abs(C))
    # On an exact law U_i is Fs times the true error of level i.
    assert s.uncertainty == pytest.approx([1.25 * abs(C) * x**p for x in h], rel=1e-6)


def test_fit_of_noisy_data_reports_its_scatter() -> None:
    # A law plus alternating +-e: the fit keeps f0 and p near the law's and sigma near e.
    h = [size_law(m) for m in PAPER_AND_FINER]
    e = 0.02
    values = [10.0 + 2.0 * x**1.5 + e * (-1) ** i for i, x in enumerate(h)]
    triples = grid_studies(values, h)
    assert any(t.kind != "monotone" for t in triples)  # the triples see oscillation
    s = fit_study(values, h)
    assert s.kind == "monotone" and s.fit == "power" and not s.scattered
    assert s.order == pytest.approx(1.5, abs=0.15)
    assert s.extrapolated == pytest.approx(10.0, abs=0.05)
    assert e * 0.8 < s.sigma < e * 1.3
    for u, v in zip(s.uncertainty, values):
        assert abs(v - 10.0) <= u  # each level's band holds the exact limit


def test_fit_outside_the_trusted_orders_uses_fixed_orders() -> None:
    h = [size_law(m) for m in PAPER_AND_FINER]
    # p = 3 and a law rising to its limit with p = 4 (2358 stage 1 has this shape): the
    # order-2 fit, whose sigma is the smaller; its limit lies beyond the data (the lower
    # order overshoots the true one), and with Fs = 3 every level's band holds the true limit.
    for f0, a, p in ((5.0, 0.5, 3.0), (9.6, -0.3, 4.0)):
        values = [f0 + a * x**p for x in h]
        s = fit_study(values, h)
        assert s.order == pytest.approx(p, rel=1e-6)
        assert (s.fit, s.safety_factor) == ("order 2", 3.0)
        assert (s.extrapolated < min(values)) if a > 0 else (s.extrapolated > max(values))
        assert all(abs(v - f0) <= u for u, v in zip(s.uncertainty, values))
    # Exactly linear data: p = 1 is inside the trusted range.
    assert fit_study([4.0 + x for x in h], h).fit == "power"


def test_fit_of_scattered_data_is_their_mean_and_spread() -> None:
    h = [size_law(m) for m in PAPER_AND_FINER]
    values = [10.0, 10.3, 9.8, 10.2, 9.9, 10.25, 9.85, 10.1]  # no trend: noise only
    s = fit_study(values, h)
    assert (s.kind, s.fit, s.scattered) == ("scattered", "mean", True)
    mean = sum(values) / 8
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / 7)
    assert s.extrapolated == pytest.approx(mean) and s.sigma == pytest.approx(sd)
    assert s.uncertainty == pytest.approx([abs(v - mean) + 2 * sd for v in values])


@pytest.mark.parametrize(
    ("values", "kind"),
    [
        ((1.0, 2.0, 4.0, 8.0), "divergent"),  # differences grow with refinement
        ((5.0, 5.0, 5.0, 5.0), "constant"),
        ((1.1e-16, 2.2e-16, 0.0, 1.1e-16), "constant"),  # roundoff about zero
        ((5.0, math.nan, 5.0, 4.0), "undefined"),
        ((5.0, 4.0, 3.5), "undefined"),  # three levels: Roache's triple, not a fit
    ],
)
def test_fit_kinds(values, kind: str) -> None:
    h = [size_law(m) for m in PAPER_AND_FINER[: len(values)]]
    s = fit_study(values, h)
    assert s.kind == kind and len(s.uncertainty) == len(values)
    if kind == "constant":
        assert s.extrapolated == values[0] and s.uncertainty == (0.0,) * 4
    else:
        assert math.isnan(s.extrapolated)


def test_fit_checks_its_sizes() -> None:
    with pytest.raises(ValueError, match="4 values but 3"):
        fit_study([1.0, 2.0, 3.0, 4.0], [3.0, 2.0, 1.0])
    with pytest.raises(ValueError, match="decrease"):
        fit_study([1.0, 2.0, 3.0, 4.0], [3.0, 2.0, 2.0, 1.0])


def test_analysed_levels_fit_the_converged_ones() -> None:
    from woundsweep.studies.convergence import analyse_levels

    h = [size_law(m) for m in PAPER_AND_FINER]
    law = [12.0 + 2.0 * x**1.5 for x in h]
    rows = [
        {
            "relative_size": x,
            "stages": {"4": {q: None for q in QUANTITIES} | {"p99_von_mises_kPa": v}},
        }
        for x, v in zip(h, law[:-1] + [None])  # the finest level did not converge
    ]
    got = analyse_levels(rows)
    fit = got["fits"]["4"]["p99_von_mises_kPa"]
    want = fit_study(law[:-1], h[:-1])
    assert fit["kind"] == want.kind == "monotone"
    assert fit["extrapolated"] == pytest.approx(12.0, rel=1e-6)
    assert fit["uncertainty"][:-1] == pytest.approx(list(want.uncertainty))
    assert math.isnan(fit["uncertainty"][-1])
    devs = got["fit_deviations"]["4"]["p99_von_mises_kPa"]
    assert devs[-1] is None and devs[0] == pytest.approx((law[0] - 12.0) / 12.0, rel=1e-5)
