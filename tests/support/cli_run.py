"""Running the woundsweep CLI from tests: as a subprocess, or through the fork server.

`generate_run(doc, where)` generates a run directory from a sweep document; `ws(*args)` runs ``python -m woundsweep ARGS`` and returns the completed process.
`ForkCli` talks to tests/support/cli_forkserver.py: ``cli(argv, cwd)`` runs
`woundsweep.cli.main` in a fresh process forked from one that imported the CLI once, with a
timeout.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any, NamedTuple

import yaml

SUPPORT = Path(__file__).resolve().parent  # tests/support
ROOT = SUPPORT.parents[1]
DEMO = ROOT / "sweeps" / "demo.yaml"
PAPER = ROOT / "sweeps" / "paper.yaml"
WS = [sys.executable, "-m", "woundsweep"]


def demo_doc() -> dict[str, Any]:
    """sweeps/demo.yaml as a fresh document (safe to edit)."""
    return yaml.safe_load(DEMO.read_text())


def generate_run(doc: dict[str, Any], where: Path, name: str = "run") -> Path:
    """Write the sweep ``doc`` to WHERE/NAME.yaml and generate the run WHERE/NAME from it
    (`woundsweep generate` in this process)."""
    from woundsweep.cli import main

    sweep = where / f"{name}.yaml"
    sweep.write_text(yaml.safe_dump(doc))
    rd = where / name
    assert main(["generate", str(sweep), "--out", str(rd)]) == 0
    return rd


def ws(
    *args: str, env: dict[str, str] | None = None, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    """``python -m woundsweep ARGS``, output captured as text."""
    return subprocess.run([*WS, *args], capture_output=True, text=True, timeout=timeout, env=env)


class Res(NamedTuple):
    code: int | None
    stdout: str
    stderr: str
    timed_out: bool


class ForkCli:
    """The fork server: ``cli(argv, cwd)`` runs one command, like ``python -m woundsweep``."""

    def __init__(self, scratch: Path) -> None:
        self.scratch = scratch
        self.n = 0
        self.proc = subprocess.Popen(
            [sys.executable, str(SUPPORT / "cli_forkserver.py")],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )

    def __call__(
        self,
        argv: list[str],
        cwd: Path,
        *,
        env: dict[str, str] | None = None,
        fsize: int | None = None,
        timeout: float = 30.0,
    ) -> Res:
        self.n += 1
        out, err = self.scratch / f"{self.n}.out", self.scratch / f"{self.n}.err"
        req = {
            "argv": argv, "cwd": str(cwd), "stdout": str(out), "stderr": str(err),
            "env": env, "fsize": fsize, "timeout": timeout,
        }  # fmt: skip
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        reply = json.loads(self.proc.stdout.readline())
        return Res(reply["code"], out.read_text(), err.read_text(), reply["timed_out"])

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(timeout=30)
