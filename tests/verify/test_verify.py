"""The verification cases (`woundsweep.verify`): the quick subset through the registry, each
case once, and the command's exit status and JSON on a planted failure."""

from __future__ import annotations

import dataclasses
import json

import pytest

pytestmark = pytest.mark.fem


def _quick():
    from woundsweep.verify.cases import select

    return select(quick=True)


@pytest.mark.parametrize("case", _quick(), ids=lambda c: c.name)
def test_quick_case_meets_its_expectation(case) -> None:
    from woundsweep.verify.report import run_cases

    (outcome,) = run_cases([case])
    assert outcome.error is None, outcome.error
    assert outcome.passed, (case.name, outcome.measured, case.expectation(), case.tolerance)


def test_cli_exits_3_on_a_failed_case_and_reports_it_in_json(monkeypatch, capsys) -> None:
    """A planted case whose expectation is wrong: exit 3, the JSON names it failed; an
    unknown case name is invalid input (exit 2)."""
    from woundsweep.cli import main
    from woundsweep.verify import cases

    good = cases.Case("planted-good", "a case that passes", 1.0, 0.1, lambda: 1.05)
    bad = dataclasses.replace(good, name="planted-bad", what="off by 10 %", run=lambda: 1.1,
                              tolerance=0.05)  # fmt: skip
    monkeypatch.setattr(cases, "CASES", (good, bad))
    assert main(["verify", "--case", "planted", "--json"]) == 3
    data = json.loads(capsys.readouterr().out)
    assert data["passed"] is False and data["failed"] == ["planted-bad"]
    assert [c["name"] for c in data["cases"]] == ["planted-good", "planted-bad"]
    assert {"measured", "expected", "tolerance", "passed", "time_s"} <= set(data["cases"][0])
    assert main(["verify", "--case", "planted-good"]) == 0
    assert "1 of 1 cases passed" in capsys.readouterr().out
    assert main(["verify", "--case", "no-such-case"]) == 2
    assert "no case named no-such-case" in capsys.readouterr().err
