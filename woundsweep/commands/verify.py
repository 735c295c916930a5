"""``woundsweep verify [--quick] [--case NAME ...] [--json] [--out DIR]``.

Runs the verification cases (`woundsweep.verify.cases`: manufactured solutions with their
rates, the slit's closed-form closure, objectivity, contact known answers, the closures'
identities) and prints a table: case, measured, expected, tolerance, result, time. Exit
status 0 when every case passes, 3 (`ExitCode.NOT_CONVERGED`, "a computation did not give
its answer") when one fails, 2 for an unknown case name. ``--out DIR`` writes the MMS
convergence plots (PNG) and ``verify.json``.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import click

from ..core.errors import WoundsweepError
from ..core.schema import ExitCode

# One BLAS / OpenMP thread, as for the other commands that solve (`cli.SERIAL_COMMANDS`),
# set before numpy loads.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__all__ = ["cmd"]


@click.command(name="verify")
@click.option("--quick", is_flag=True, help="The minute-scale subset (what CI runs).")
@click.option("--case", "names", multiple=True, metavar="NAME",
              help="Only the cases whose name starts with NAME (repeatable).")  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON instead.")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Directory for the MMS convergence plots and verify.json.")  # fmt: skip
@click.option("--list", "list_only", is_flag=True, help="List the cases and exit.")
def cmd(quick: bool, names: tuple[str, ...], as_json: bool, out: Path | None,
        list_only: bool) -> None:  # fmt: skip
    """Verification: manufactured solutions (rates), the slit's closed-form closure,
    objectivity, contact known answers; exit 3 if a case fails."""
    import logging

    logging.getLogger().setLevel(logging.WARNING)  # FFCx's compile messages
    from ..core.fsutil import check_output_dir
    from ..verify import cases as registry

    try:
        chosen = registry.select(quick, names)
    except KeyError as exc:
        raise WoundsweepError(f"verify: no case named {exc.args[0]} (see --list)") from None
    if list_only:
        for c in chosen:
            click.echo(f"{c.name:<40} {'quick' if c.quick else 'full ':<6} {c.what}")
        return
    if out is not None:
        try:
            check_output_dir(out)
        except ValueError as err:
            raise WoundsweepError(f"--out {err}") from None
    from ..physics.compat import DOLFINX_VERSION
    from ..verify import report

    t0 = time.perf_counter()
    if not as_json:
        click.echo(f"woundsweep verify: {len(chosen)} cases, DOLFINx {DOLFINX_VERSION}")
        click.echo(report.table([])[0])
    outcomes = report.run_cases(chosen, None if as_json else lambda o: click.echo(report.row(o)))
    total = time.perf_counter() - t0
    text = report.to_json(outcomes, total, DOLFINX_VERSION)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "verify.json").write_text(text + "\n")
        report.plot_studies(out)
    failed = [o.case.name for o in outcomes if not o.passed]
    if as_json:
        click.echo(text)
    else:
        if report.studies():
            click.echo("\nMMS rates (least-squares fit of log error against log h):")
            for line in report.rates_table():
                click.echo(line)
        click.echo(f"\n{len(outcomes) - len(failed)} of {len(outcomes)} cases passed "
                   f"in {total:.0f} s" + (f"; failed: {', '.join(failed)}" if failed else ""))  # fmt: skip
    if failed:
        raise click.exceptions.Exit(int(ExitCode.NOT_CONVERGED))
