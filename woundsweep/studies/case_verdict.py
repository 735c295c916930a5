"""The verdicts of a case's report (`woundsweep case`), each computed once and read by every
sentence that states it: where the wound is open (a surface gap above `OPEN_GAP_mm`), what a
load after closure opens, which sutures carry most, and the margin of the largest force
against the force at which a suture tears through skin (`case_literature`).

A load "opens" the wound where a surface point closed after suturing has a gap above the
threshold at any converged step of the load. The wound "holds" under a load when every step
converged, nothing opens and the largest suture force stays below the lowest tear-through
force; the model's sutures never fail, so the margin is that force over the largest one.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..config.case import OPEN_GAP_mm, line_angle
from ..physics.suture_measures import SutureState
from .case import CaseResult, LoadRun
from .case_literature import TEAR_THROUGH

__all__ = [
    "GROW_MIN_mm",
    "LoadVerdict",
    "Stretch",
    "Verdict",
    "beyond_ends",
    "carry_least",
    "carry_most",
    "open_stretches",
    "verdict",
]

# A gap that changes by less than this is reported as unchanged (the report prints 0.001 mm).
GROW_MIN_mm = 0.001


class Stretch(NamedTuple):
    """A run of surface points along the wound (y from y0 to y1, mm) and its largest gap."""

    y0_mm: float
    y1_mm: float
    gap_max_mm: float


def open_stretches(y: np.ndarray, gap: np.ndarray, threshold: float = OPEN_GAP_mm) -> list[Stretch]:
    """The runs of consecutive surface points (sorted by y) whose gap is above ``threshold``."""
    return _runs(np.asarray(y, float), np.asarray(gap, float), np.asarray(gap) > threshold)


def _runs(y: np.ndarray, gap: np.ndarray, mask: np.ndarray) -> list[Stretch]:
    out = []
    i, n = 0, len(mask)
    while i < n:
        if not mask[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and mask[j + 1]:
            j += 1
        out.append(Stretch(float(y[i]), float(y[j]), float(gap[i : j + 1].max())))
        i = j + 1
    return out


class LoadVerdict(NamedTuple):
    """What one load after closure does (module docstring)."""

    to_wound_deg: float
    to_langer_deg: float  # 0-90
    steps_done: int
    steps: int
    before: SutureState
    last: SutureState | None  # the last converged step's state
    open_after: list[Stretch]  # open at the last converged step
    opened: list[Stretch]  # closed after suturing, open at some step (largest gap over the steps)
    first_step: int | None  # the first step at which a closed point opens
    grows: tuple[float, float, float] | None  # (y, gap before, after) of the largest growth

    @property
    def completed(self) -> bool:
        return self.steps_done == self.steps

    @property
    def opens(self) -> bool:
        return bool(self.opened)

    @property
    def opened_only_beyond_ends(self) -> bool:
        """Every stretch the load opens lies beyond the end sutures (toward an apex)."""
        return beyond_ends(self.opened, self.before.suture_y_mm)

    @property
    def peak_force_mN(self) -> float:
        st = self.last if self.last is not None else self.before
        return float(st.suture_force_mN.max())


def load_verdict(before: SutureState, run: LoadRun, threshold: float = OPEN_GAP_mm) -> LoadVerdict:
    """The verdict of ``run`` from the sutured state ``before``."""
    done = [s.state for s in run.steps if s.state is not None]
    closed = before.gap_mm <= threshold
    opened: list[Stretch] = []
    first = None
    last = done[-1] if done else None
    grows = None
    if done:
        gaps = np.stack([st.gap_mm for st in done])
        for j, g in enumerate(gaps, 1):
            if first is None and np.any(closed & (g > threshold)):
                first = j
        worst = gaps.max(axis=0)
        opened = _runs(before.gap_y_mm, worst, closed & (worst > threshold))
        growth = last.gap_mm - before.gap_mm  # type: ignore[union-attr]
        i = int(np.argmax(growth))
        if growth[i] >= GROW_MIN_mm:
            grows = (float(before.gap_y_mm[i]), float(before.gap_mm[i]), float(last.gap_mm[i]))  # type: ignore[union-attr]
    return LoadVerdict(
        run.to_wound_deg,
        abs(line_angle(run.load.angle_to_langer_deg)),
        _converged_prefix(run),
        len(run.steps),
        before,
        last,
        open_stretches(last.gap_y_mm, last.gap_mm, threshold) if last is not None else [],
        opened,
        first,
        grows,
    )


def _converged_prefix(run: LoadRun) -> int:
    n = 0
    for s in run.steps:
        if s.state is None:
            break
        n += 1
    return n


class Verdict(NamedTuple):
    """The report's verdicts (module docstring)."""

    threshold_mm: float
    after_closure: list[Stretch]  # open after suturing
    load: LoadVerdict
    scan: list[LoadVerdict]  # the case's load and the scan's, by angle to the wound
    tear_through_N: float  # the lowest force at which a suture tears through

    @property
    def closed(self) -> bool:
        """Closed after suturing: no surface gap above the threshold."""
        return not self.after_closure

    @property
    def open_only_beyond_ends(self) -> bool:
        """Every open stretch after suturing lies beyond the end sutures (toward an apex)."""
        return beyond_ends(self.after_closure, self.load.before.suture_y_mm)

    @property
    def sutures_hold(self) -> bool:
        """The largest force under the load stays below the lowest tear-through force."""
        return self.load.peak_force_mN < 1e3 * self.tear_through_N

    @property
    def holds(self) -> bool | None:
        """The wound holds under the load (module docstring); None: the load was not
        followed to its end."""
        if not self.load.completed:
            return None
        return not self.load.opens and self.sutures_hold

    @property
    def margin(self) -> float:
        """The lowest tear-through force over the largest force under the load."""
        return 1e3 * self.tear_through_N / max(self.load.peak_force_mN, 1e-9)

    @property
    def worst(self) -> LoadVerdict:
        """Of the directions solved, the load with the largest suture force at its end."""
        return max(self.scan, key=lambda v: v.peak_force_mN)


def verdict(result: CaseResult, threshold: float = OPEN_GAP_mm) -> Verdict:
    """The verdicts of ``result``."""
    st = result.sutured
    main = load_verdict(st, result.loaded, threshold)
    scan = [main] + [load_verdict(st, run, threshold) for run in result.scan]
    scan.sort(key=lambda v: v.to_wound_deg)
    return Verdict(
        threshold,
        open_stretches(st.gap_y_mm, st.gap_mm, threshold),
        main,
        scan,
        TEAR_THROUGH.low_N,
    )


def carry_most(state: SutureState, rel: float = 0.01) -> list[int]:
    """The indices of the sutures whose force is within ``rel`` of the largest."""
    f = state.suture_force_mN
    return [int(i) for i in np.flatnonzero(f >= (1 - rel) * f.max())]


def carry_least(state: SutureState, rel: float = 0.01) -> list[int]:
    """The indices of the sutures whose force is within ``rel`` of the smallest."""
    f = state.suture_force_mN
    return [int(i) for i in np.flatnonzero(f <= (1 + rel) * f.min())]


def beyond_ends(stretches: list[Stretch], ys: np.ndarray) -> bool:
    """Every stretch lies beyond the outermost sutures at ``ys`` (toward an apex)."""
    return all(s.y0_mm > ys.max() or s.y1_mm < ys.min() for s in stretches)
