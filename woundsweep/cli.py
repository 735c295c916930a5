"""Command-line interface: ``woundsweep COMMAND``.

Each command lives in ``woundsweep/commands/<name>.py`` as a click command named ``cmd``
and is listed in ``COMMANDS``; modules are imported lazily so that ``--help`` stays fast
and commands that do not need DOLFINx never import it.
"""

from __future__ import annotations

import importlib
import io
import logging
import os
import re
import signal
import sys
import warnings
from typing import Any, NoReturn

import click

from . import __version__
from .core.errors import Interrupted, WoundsweepError, one_line, report

__all__ = ["COMMANDS", "SERIAL_COMMANDS", "main", "serial_blas"]

# name -> (module, one-line help). Only commands that work are listed.
COMMANDS: dict[str, tuple[str, str]] = {
    "generate": (
        "woundsweep.commands.generate",
        "Expand a sweep YAML into RUN_DIR/manifest.parquet.",
    ),
    "mesh": (
        "woundsweep.commands.mesh",
        "Build or reuse the tetrahedral meshes of wound geometries; --out FILE.vtu.",
    ),
    "solve": (
        "woundsweep.commands.solve",
        "Solve one job through the stages in-process; writes its HDF5 result.",
    ),
    "converge": (
        "woundsweep.commands.converge",
        "Solve one job on refined meshes: observed order, GCI, extrapolated values.",
    ),
    "run": (
        "woundsweep.commands.run",
        "Run a shard of the jobs, each in its own process, into RUN_DIR's store.",
    ),
    "status": (
        "woundsweep.commands.status",
        "Counts by failure class and stage, throughput, CPU time left.",
    ),
    "pack": (
        "woundsweep.commands.pack",
        "Merge a run's finished results into one compact Parquet table (no fields).",
    ),
    "unpack": (
        "woundsweep.commands.unpack",
        "Write a packed table's jobs into a run's store; `run` then skips them.",
    ),
    "analyze": (
        "woundsweep.commands.analyze",
        "Stress-quantile model (XGBoost), evaluation, figures, report.",
    ),
    "predict": (
        "woundsweep.commands.predict",
        "Predicted stress of one wound (or a table of wounds, --table) from an analyzed run.",
    ),
    "slurm": (
        "woundsweep.commands.slurm",
        "SLURM scripts for the sweep: warm-up, job array of shards, follow-up; --submit.",
    ),
    "export": (
        "woundsweep.commands.export",
        "ParaView series (PVD + VTU) of stored jobs: displacement, von Mises, tags.",
    ),
    "view": (
        "woundsweep.commands.view",
        "One job's interactive 3D view as a self-contained HTML file.",
    ),
    "atlas": (
        "woundsweep.commands.atlas",
        "Static site of a run: index of every job, job pages with 3D views, analysis.",
    ),
    "case": (
        "woundsweep.commands.case",
        "One clinical case: an elliptical excision closed by sutures; report with forces.",
    ),
    "verify": (
        "woundsweep.commands.verify",
        "Verification cases: manufactured-solution rates, closed forms, contact known answers.",
    ),
}


def missing_required(cmd: click.Command, ctx: click.Context, args: list[str]) -> list[str]:
    """Every required option or argument of ``cmd`` that ``args`` leaves out (in the order
    of ``--help``), so that one message names them all; [] when the arguments do not
    parse (click then reports that) or ask for help."""
    if any(a in ctx.help_option_names for a in args):
        return []
    # Not resilient: an unknown option anywhere is click's to report (a resilient parse
    # would stop at it and count the arguments after it as missing).
    sub = click.Context(cmd, info_name=cmd.name, parent=ctx)
    try:
        opts, _, _ = cmd.make_parser(sub).parse_args(args=list(args))
    except click.ClickException:
        return []
    names = []
    unset = getattr(click.core, "UNSET", None)  # click >= 8.3 marks absent values with it
    for param in cmd.get_params(sub):
        value = opts.get(param.name)
        if not param.required or not (value is None or value is unset or value == ()):
            continue
        if param.resolve_envvar_value(sub) is not None:
            continue
        if isinstance(param, click.Option):
            names.append(max(param.opts, key=len))
        else:
            # click's stubs declare one make_metavar signature (ctx from 8.2 on); the other
            # branch serves the other click versions, so which call errs depends on the version.
            names.append(
                param.make_metavar(sub)  # type: ignore[call-arg, unused-ignore]
                if _METAVAR_TAKES_CTX
                else param.make_metavar()  # type: ignore[call-arg, unused-ignore]
            )
    return names


try:  # click >= 8.2 passes the context to make_metavar
    import inspect

    _METAVAR_TAKES_CTX = "ctx" in inspect.signature(click.Argument.make_metavar).parameters
except (TypeError, ValueError):  # pragma: no cover
    _METAVAR_TAKES_CTX = False


# Commands whose processes solve one job at a time: BLAS and OpenMP run one thread. A
# threaded OpenBLAS spends its time waking threads on the solver's batches of 3 x 3 matrices
# (seconds a call when the cores are busy with sibling jobs), and the thread count is fixed
# when numpy loads, so it is set before the command's module is imported.
SERIAL_COMMANDS = frozenset({"solve", "converge", "case", "run"})
_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def serial_blas() -> None:
    """One BLAS / OpenMP thread unless the environment says otherwise."""
    for var in _THREAD_VARS:
        os.environ.setdefault(var, "1")


def check_tmpdir() -> None:
    """WoundsweepError unless ``$TMPDIR`` (when set) is a directory a file can be made in:
    MPI, which the solving commands start, puts its session directory there and otherwise
    ends the process with a long banner."""
    import tempfile

    where = os.environ.get("TMPDIR")
    if not where:
        return
    try:
        with tempfile.TemporaryFile(prefix=".woundsweep-check.", dir=where):
            pass
    except OSError as err:
        raise WoundsweepError(
            f"TMPDIR={where}: cannot make a temporary file there ({err.strerror}); set TMPDIR "
            "to a writable directory"
        ) from None


class LazyGroup(click.Group):
    def resolve_command(
        self, ctx: click.Context, args: list[str]
    ) -> tuple[str | None, click.Command | None, list[str]]:
        name, cmd, rest = super().resolve_command(ctx, args)
        if cmd is not None:
            missing = missing_required(cmd, ctx, rest)
            if len(missing) > 1:
                raise click.UsageError(f"{name}: missing {', '.join(missing)} (see --help)")
            if name in SERIAL_COMMANDS and not any(a in ctx.help_option_names for a in rest):
                check_tmpdir()
        return name, cmd, rest

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        if name in SERIAL_COMMANDS:
            serial_blas()
        return importlib.import_module(COMMANDS[name][0]).cmd

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, help_) for name, (_, help_) in COMMANDS.items()]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="woundsweep")
def cli() -> None:
    """Finite-element atlas of wound closure in two-layer hyperelastic skin.

    Units: lengths in mm, stresses in kPa, forces in mN.
    Typical use: generate -> run -> analyze.
    """


def _interrupt(signum: int, frame: object) -> None:
    raise Interrupted()


# On Python >= 3.14 the resource tracker that multiprocessing starts for a library's
# semaphore reports it as leaked when its process (this one, or the fork server it starts) is
# killed or exits early, and removes it: a warning on the command's stderr that is not the
# command's message. Processes started from here inherit the filter through the environment.
_TRACKER_WARNING = "ignore:resource_tracker:UserWarning"


def _quiet_resource_tracker() -> None:
    current = os.environ.get("PYTHONWARNINGS", "")
    if _TRACKER_WARNING not in current.split(","):
        os.environ["PYTHONWARNINGS"] = ",".join(w for w in (current, _TRACKER_WARNING) if w)


# Control characters other than tab and newline, as the standard output shows them escaped.
_STDOUT_CONTROL = re.compile(rb"[\x00-\x08\x0b-\x1f\x7f]")


class _EscapingStdout(io.RawIOBase):
    """The standard output's bytes with control characters escaped (``\\x1b``): a path
    printed by a command cannot move the cursor or rewrite the terminal's lines."""

    def __init__(self, sink: Any) -> None:
        self.sink = sink

    def writable(self) -> bool:
        return True

    def write(self, data: Any) -> int:
        raw = bytes(data)
        self.sink.write(_STDOUT_CONTROL.sub(lambda m: b"\\x%02x" % m.group()[0], raw))
        return len(raw)

    def flush(self) -> None:
        self.sink.flush()


def _closed(fd: int) -> bool:
    try:
        os.fstat(fd)
    except OSError:
        return True
    return False


def _standard_streams() -> int | None:
    """Standard streams a command can use: a closed standard input or error reads or
    writes /dev/null (so no file the command opens takes its descriptor); a closed standard
    output is refused (exit status 2), as the command's output would be lost."""
    for fd in (0, 2, 1):
        if _closed(fd):
            null = os.open(os.devnull, os.O_RDWR)
            if null != fd:
                os.dup2(null, fd)
                os.close(null)
            name = ("stdin", "stdout", "stderr")[fd]
            if getattr(sys, name) is None:
                setattr(sys, name, open(fd, "r" if fd == 0 else "w", closefd=False))  # noqa: SIM115
            if fd == 1:
                print("woundsweep: error: standard output is closed", file=sys.stderr, flush=True)
                return 2
    return None


def main(argv: list[str] | None = None) -> int:
    """Entry point: user errors become one line on stderr and exit status 2 (no traceback)."""
    closed = _standard_streams()
    if closed is not None:
        return closed
    stdout = sys.stdout
    if hasattr(stdout, "buffer"):
        stdout.flush()
        sys.stdout = io.TextIOWrapper(
            _EscapingStdout(stdout.buffer),
            encoding=stdout.encoding, errors=stdout.errors, write_through=True,
        )  # fmt: skip
    try:
        with warnings.catch_warnings():
            if not sys.warnoptions:  # libraries' warnings (numpy, matplotlib) are not the
                warnings.simplefilter("ignore")  # command's output; PYTHONWARNINGS shows them
            return _main(argv)
    finally:
        if sys.stdout is not stdout:
            sys.stdout.flush()
            sys.stdout = stdout


def _main(argv: list[str] | None) -> int:
    _quiet_resource_tracker()
    old = None
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        try:
            old = signal.signal(signal.SIGINT, _interrupt)
        except ValueError:  # not the main thread: Ctrl-C stays Python's
            old = None
    try:
        # With standalone_mode=False click returns ctx.exit()'s code instead of raising Exit.
        rv = cli.main(args=argv, prog_name="woundsweep", standalone_mode=False)
    except WoundsweepError as err:
        return report(err)
    except (Interrupted, click.exceptions.Abort):
        print("woundsweep: interrupted", file=sys.stderr, flush=True)
        return Interrupted.exit_code
    except click.ClickException as err:
        click.echo(one_line(f"woundsweep: error: {err.format_message()}"), err=True)
        return 2
    except click.exceptions.Exit as err:
        return err.exit_code
    except OSError as err:  # a filesystem error on a path no command anticipated: one line too
        return report(err)
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)
    return rv if isinstance(rv, int) else 0


def console_main() -> NoReturn:
    """Console-script and ``python -m woundsweep`` entry: `main`, then exit at once.

    Standard streams and logging are flushed, but the interpreter's teardown is skipped:
    pyarrow's thread pools can abort it (``std::terminate`` from a still-joinable thread,
    apache/arrow#34314), which would turn a finished command into SIGABRT.
    Every file the commands write is closed (and atomically renamed) before they return.
    """
    exit_now(main())


def exit_now(code: int) -> NoReturn:
    """Flush logging and the standard streams, then end the process without teardown."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


if __name__ == "__main__":
    console_main()
