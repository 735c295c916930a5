"""What an analysis was trained on, and whether the run has moved on since.

`analyze` records in ``metrics.json`` and in each model's metadata (key ``trained_on``) the
run's `settings_fingerprint` (its sweep's settings for every manifest job) and the
`results_fingerprint` of the result rows it read. `stale_note` compares a record with the run
as it is now: `predict` checks the settings (cheap: no result file is read), `atlas`, which
reads the results anyway, both.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from ..config.manifest import Run, load_run
from ..core.layout import RunLayout
from ..store.identity import results_fingerprint, settings_fingerprint

__all__ = ["model_run_dir", "stale_note", "trained_on"]


def _settings(run: Run | None) -> str | None:
    return None if run is None else settings_fingerprint(run.sweep, run.manifest)


def trained_on(run: Run | None, results: pd.DataFrame) -> dict[str, Any]:
    """The record of an analysis of ``run`` (None: a result store without a sweep) that
    read ``results``."""
    return {
        "settings_fingerprint": _settings(run),
        "results_fingerprint": results_fingerprint(results),
        "result_rows": int(len(results)),
    }


def model_run_dir(model_path: Path) -> Path | None:
    """The run directory of a model file in ``RUN_DIR/analysis/`` (None elsewhere)."""
    folder = model_path.resolve().parent
    rd = folder.parent
    return rd if folder == RunLayout(rd).analysis_dir else None


def stale_note(
    run_dir: Path,
    record: Mapping[str, Any] | None,
    results: pd.DataFrame | None = None,
    run: Run | None = None,
) -> str:
    """ "" if the analysis recorded by ``record`` matches the run now, else why not (the
    results are compared only when given). ``run`` is the run directory already loaded, if
    the caller has it."""
    layout = RunLayout(run_dir)
    where = layout.analysis_dir
    if not isinstance(record, Mapping):
        return f"{where} does not record what it was trained on; rerun `woundsweep analyze`"
    if run is None and layout.is_run():
        run = load_run(run_dir)
    if record.get("settings_fingerprint") != _settings(run):
        return (
            f"{where} is stale: the run's sweep or manifest changed since it was trained "
            f"(rerun `woundsweep analyze {run_dir}`)"
        )
    if results is not None and record.get("results_fingerprint") != results_fingerprint(results):
        return (
            f"{where} is stale: trained on {record.get('result_rows')} result rows, the store now "
            f"holds other results ({len(results)} rows; rerun `woundsweep analyze {run_dir}`)"
        )
    return ""
