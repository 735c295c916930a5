"""Run woundsweep's real CLI entry point once per request, each in a fresh forked process.

Started as a subprocess by `ForkCli` (tests/support/cli_run.py). It imports the CLI once and
then, per JSON request on stdin (one line: argv, cwd, stdout/stderr file paths, optional env
and file size limit, timeout), forks a child that does what ``python -m woundsweep ARGV`` does
(`woundsweep.cli.main`, then exit with its status, an uncaught exception printing its
traceback and exiting 1 as the interpreter would) with stdin from /dev/null. The server
itself runs no command, so each child starts from the same state. It answers with one JSON
line: the exit status (negative for a signal) and whether the child was killed for the
timeout. This makes hundreds of real CLI runs take seconds instead of minutes of start-up.
"""

from __future__ import annotations

import json
import os
import resource
import signal
import sys
import time
import traceback

import woundsweep.cli
import woundsweep.commands.generate
import woundsweep.commands.run
import woundsweep.commands.slurm
import woundsweep.commands.status  # noqa: F401 - imported once here, not in every child


def _child(req: dict) -> None:
    os.chdir(req["cwd"])
    os.environ.update(req.get("env") or {})
    fd = os.open(os.devnull, os.O_RDONLY)
    os.dup2(fd, 0)
    for target, name in ((1, "stdout"), (2, "stderr")):
        out = os.open(req[name], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(out, target)
        os.close(out)
    if req.get("fsize") is not None:  # a full disk: writes past the limit fail (EFBIG)
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (req["fsize"], req["fsize"]))
    try:
        code = woundsweep.cli.main(req["argv"])
    except SystemExit as err:
        code = err.code if isinstance(err.code, int) else 1
    except BaseException:  # noqa: BLE001 - what the interpreter would print for it
        traceback.print_exc()
        code = 1
    woundsweep.cli.exit_now(code)


def _serve(req: dict) -> dict:
    pid = os.fork()
    if pid == 0:
        try:
            _child(req)
        finally:
            os._exit(111)
    deadline = time.monotonic() + float(req.get("timeout", 30))
    while True:
        wpid, status = os.waitpid(pid, os.WNOHANG)
        if wpid == pid:
            code = os.waitstatus_to_exitcode(status)
            return {"code": code, "timed_out": False}
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return {"code": None, "timed_out": True}
        time.sleep(0.002)


def main() -> None:
    for line in sys.stdin:
        if not line.strip():
            continue
        reply = _serve(json.loads(line))
        sys.stdout.write(json.dumps(reply) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
