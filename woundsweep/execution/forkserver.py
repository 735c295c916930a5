"""The fork server: one process per runner that has the solver stack imported and forks a
fresh child for each job attempt.

A job attempt is still its own process, in its own session and process group, so a crash,
a hang or an allocation runaway costs that attempt only, and the runner kills it with its
group (`woundsweep.execution.process`). What the server saves is the start: the child
of a fork has DOLFINx, UFL, FFCx, PETSc, MPI and the `woundsweep` solve path imported and
initialised already (about 1-3 s a job otherwise).

The runner (`ForkServer`) talks to the server over a socket pair, one JSON object a line:
``{"id", "job", "env", "cwd", "log", "as_limit"}`` asks for a child that runs the job function
`woundsweep.physics.entry.run_job` on ``job`` (a `JobRequest`: what ``woundsweep solve`` runs)
with stdout and stderr appended to ``log``; the server answers ``{"id", "pid"}`` and, when the child ends,
``{"exit": pid, "status", "utime", "stime", "maxrss"}`` (its ``wait4`` status and rusage).
The server reaps its children; the runner still polls their memory and kills their groups.

Contracts of the server process:

- It imports, it never computes: no mesh, no form, no JIT compile, no file of a run; so it
  holds no FFCx lock (`jitlock` does not count it as a process that could be compiling) and
  has no state a job could inherit.
- It starts with the runner's environment, so what libraries read when they load
  (``OPENBLAS_NUM_THREADS``, ...) is as for a job; a child then takes the job's environment.
  MPI is initialised once, as a singleton without a helper daemon
  (``OMPI_MCA_ess_singleton_isolated``), so the children share no connection to one.
- It dies with the runner (``PR_SET_PDEATHSIG``), and its children die with it. If it dies
  anyway, its running attempts end as killed by SIGKILL (transient, so retried) and the next
  attempt starts a new server.

In the child the signal dispositions are reset to a fresh interpreter's (PETSc's handlers,
installed at import, are dropped), and with ``PYTHONFAULTHANDLER`` set a fatal signal writes
the Python traceback to the job's log and then ends the child with that signal.
"""

from __future__ import annotations

import faulthandler
import importlib
import json
import logging
import os
import select
import signal
import socket
import subprocess
import sys
import time
import traceback
import warnings
from pathlib import Path
from typing import Any, NamedTuple

from ..core.errors import WoundsweepError
from .process import JOB_NAME, SERVER_NAME, Child, kill_group, preexec, set_process_name

__all__ = ["ForkServer", "ForkServerError", "JobRequest", "Usage", "serve"]

# What a job imports, in dependency order. Best effort: a module that fails to import here
# fails again in the child, which reports it in the job's log as a job without a server would.
PRELOAD = (
    "numpy",
    "scipy.sparse",
    "pandas",
    "pyarrow.parquet",
    "h5py",
    "woundsweep.physics.entry",
    "woundsweep.config.manifest",
    "woundsweep.mesh.cache",
    "woundsweep.store.solverfile",
    "woundsweep.physics.job",
    "woundsweep.physics.stages",
)


class JobRequest(NamedTuple):
    """One job attempt: manifest job ``job_index`` of ``run_dir``, stages A-B, solver file
    ``out``."""

    run_dir: str
    job_index: int
    stages: tuple[int, int]
    out: str
    fingerprint: str = ""  # the result fingerprint the runner stamps: the job must match it

    def command(self) -> list[str]:
        """The equivalent command line (``python -m woundsweep solve ...``)."""
        a, b = self.stages
        return [
            sys.executable, "-m", "woundsweep", "solve", self.run_dir,
            "--job", str(self.job_index), "--stages", f"{a}-{b}", "--out", self.out,
        ]  # fmt: skip


START_TIMEOUT_S = 600.0  # a cold import on a loaded node or a slow shared filesystem
REPLY_TIMEOUT_S = 60.0  # a fork takes milliseconds


class ForkServerError(WoundsweepError):
    """The fork server could not be started or stopped answering."""

    exit_code = 1


class Usage(NamedTuple):
    """The rusage fields of an ended child the runner uses."""

    ru_utime: float
    ru_stime: float
    ru_maxrss: int  # KiB


# -- the runner's side ---------------------------------------------------------------------
class ForkServer:
    """Starts the server on first use and restarts it if it died; see the module docstring."""

    def __init__(self, env: dict[str, str], label: str = "") -> None:
        self.env = dict(env)
        self.label = label  # shown in ps (the run directory)
        self.proc: subprocess.Popen[bytes] | None = None
        self.sock: socket.socket | None = None
        self.buf = b""
        self.next_id = 0
        self.children: dict[int, str] = {}  # running pid -> its log
        self.exited: dict[int, tuple[int, Usage | None]] = {}

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc is not None else None

    def _start(self) -> None:
        ours, theirs = socket.socketpair()
        cmd = [sys.executable, "-m", "woundsweep.execution.forkserver", str(theirs.fileno())]
        if self.label:
            cmd.append(self.label)
        with theirs:
            self.proc = subprocess.Popen(
                cmd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                env=self.env,
                start_new_session=True,
                preexec_fn=preexec(None),
                pass_fds=(theirs.fileno(),),
            )
        self.sock, self.buf = ours, b""
        msg = self._read("ready", True, START_TIMEOUT_S)
        if msg is None:
            self._stop()
            raise ForkServerError("the fork server did not start (see the messages above)")
        for name, err in msg.get("preload_failed", {}).items():
            print(f"woundsweep run: fork server: cannot import {name}: {err}", file=sys.stderr)

    def _messages(self, timeout: float) -> list[dict[str, Any]] | None:
        """What the server sent within ``timeout`` s (exit reports filed); None once it is gone."""
        assert self.sock is not None
        if not select.select([self.sock], [], [], timeout)[0]:
            return []
        try:
            data = self.sock.recv(1 << 16)
        except OSError:
            data = b""
        if not data:
            return None
        *lines, self.buf = (self.buf + data).split(b"\n")
        msgs = [json.loads(line) for line in lines]
        for msg in msgs:
            if "exit" in msg:
                self._exit_report(msg)
        return [m for m in msgs if "exit" not in m]

    def _read(self, key: str, value: Any, timeout: float) -> dict[str, Any] | None:
        """The first message with ``msg[key] == value`` (None: timeout or the server gone)."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            msgs = self._messages(min(left, 1.0))
            if msgs is None:
                return None
            for msg in msgs:
                if msg.get(key) == value:
                    return msg
        return None

    def _exit_report(self, msg: dict[str, Any]) -> None:
        pid = int(msg["exit"])
        self.children.pop(pid, None)
        usage = Usage(float(msg["utime"]), float(msg["stime"]), int(msg["maxrss"]))
        self.exited[pid] = (int(msg["status"]), usage)

    def _stop(self) -> int | None:
        """The server is gone or given up on: its running children end as SIGKILLed.
        Returns the server's exit status (as Popen's returncode)."""
        code = None
        if self.proc is not None:
            kill_group(self.proc.pid)
            code = self.proc.wait()
        if self.sock is not None:
            self.sock.close()
        for pid, log in self.children.items():
            kill_group(pid)  # PR_SET_PDEATHSIG has done it already; strays of the group
            try:
                fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_NOFOLLOW | os.O_NONBLOCK)
                with os.fdopen(fd, "ab") as fh:
                    fh.write(b"=== the fork server ended; this attempt was killed with it\n")
            except OSError:
                pass
            self.exited[pid] = (signal.SIGKILL, None)  # a wait status: killed by SIGKILL
        self.children.clear()
        self.proc, self.sock = None, None
        return code

    def spawn(self, job: JobRequest, env: dict[str, str], log: Path, as_limit: int | None) -> Child:
        """Start ``job`` in a forked child; stdout and stderr append to ``log``."""
        for attempt in (1, 2):
            if self.proc is None:
                self._start()
            self.next_id += 1
            req = {
                "id": self.next_id,
                "job": job._asdict(),
                "env": env,
                "cwd": os.getcwd(),
                "log": str(log),
                "as_limit": as_limit,
            }
            assert self.sock is not None
            try:
                self.sock.sendall(json.dumps(req).encode() + b"\n")
            except OSError:
                msg = None
            else:
                msg = self._read("id", self.next_id, REPLY_TIMEOUT_S)
            if msg is not None and "pid" in msg:
                pid = int(msg["pid"])
                self.children[pid] = str(log)
                return Child(pid)
            if msg is not None:  # the server answered but could not fork
                raise ForkServerError(f"fork server: {msg.get('error', 'no child')}")
            self._stop()
            if attempt == 1:
                print("woundsweep run: the fork server ended; starting it again", file=sys.stderr)
        raise ForkServerError("the fork server keeps ending; see the messages above")

    def wait4(self, pid: int) -> tuple[int, int, Usage | None]:
        """Like ``os.wait4(pid, os.WNOHANG)``: ``(pid, status, usage)`` once ended, else 0s."""
        if pid not in self.exited and self.sock is not None and self._messages(0.0) is None:
            running = len(self.children)
            code = self._stop()
            print(
                f"woundsweep run: the fork server ended (returncode {code}); {running} running"
                " attempt(s) killed with it; the next attempt starts a new one",
                file=sys.stderr,
            )
        if pid in self.exited:
            status, usage = self.exited.pop(pid)
            return pid, status, usage
        if pid not in self.children:  # not ours, or reported and collected already
            raise ChildProcessError(pid)
        return 0, 0, None

    def wait_any(self, timeout: float) -> None:
        """Sleep ``timeout`` s, or less: until a child's end is reported (or one is pending)."""
        if self.exited:
            return
        if self.sock is None:
            time.sleep(timeout)
        else:
            self._messages(timeout)  # if the server is gone, the next `wait4` says so

    def wait(self, pid: int, timeout: float = 10.0) -> None:
        """Wait (at most ``timeout`` s) until the server has reaped ``pid``."""
        deadline = time.monotonic() + timeout
        while pid in self.children and time.monotonic() < deadline:
            try:
                if self.wait4(pid)[0]:
                    return
            except ChildProcessError:
                return
            time.sleep(0.01)
        self.exited.pop(pid, None)

    def close(self) -> None:
        """Stop the server (it kills any child still running first)."""
        if self.proc is None:
            return
        assert self.sock is not None
        self.sock.close()  # EOF: the server kills what is left and exits
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            kill_group(self.proc.pid)
            self.proc.wait()
        self.proc, self.sock = None, None
        self.children.clear()


# -- the server's side ---------------------------------------------------------------------
def _preload() -> dict[str, str]:
    """Import `PRELOAD`; returns the modules that failed, with their errors."""
    os.environ.setdefault("OMPI_MCA_ess_singleton_isolated", "1")
    failed = {}
    for name in PRELOAD:
        try:
            importlib.import_module(name)
        except Exception as err:  # the child meets it again and logs it in the job's log
            failed[name] = f"{type(err).__name__}: {err}"[:300]
    return failed


def _reset_signals() -> None:
    """Signal dispositions of a fresh interpreter (PETSc replaced most at its import)."""
    for sig in signal.valid_signals():
        if sig in (signal.SIGKILL, signal.SIGSTOP):
            continue
        try:
            signal.signal(sig, signal.SIG_DFL)
        except (OSError, ValueError):
            continue  # signals the C library reserves for itself
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


def _child(req: dict[str, Any], server_pid: int, server_fds: tuple[int, ...]) -> None:
    """In the forked child: become the job's process and run the job function. Never returns."""
    code = 1
    try:
        os.setsid()
        preexec(req["as_limit"])()
        if os.getppid() != server_pid:  # the server died before the death signal was set
            os._exit(1)
        signal.set_wakeup_fd(-1)
        for fd in server_fds:
            os.close(fd)
        _reset_signals()
        # the runner checked the log (a regular file); a link put there since is not followed
        log = os.open(req["log"], os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(log, 1)
        os.dup2(log, 2)
        os.close(log)
        os.close(null)
        set_process_name(JOB_NAME)
        os.chdir(req["cwd"])
        os.environ.clear()
        os.environ.update(req["env"])
        job = JobRequest(**{**req["job"], "stages": tuple(req["job"]["stages"])})
        sys.argv = job.command()[2:]
        faulthandler.disable()  # its handlers were overwritten; disable forgets them
        if os.environ.get("PYTHONFAULTHANDLER"):
            faulthandler.enable(sys.stderr)
        from ..physics.entry import run_job

        code = run_job(job.run_dir, job.job_index, job.stages, job.out, job.fingerprint)
    except SystemExit as err:
        code = err.code if isinstance(err.code, int) else 1
    except BaseException:
        traceback.print_exc()
    finally:
        try:
            logging.shutdown()
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def _send(sock: socket.socket, msg: dict[str, Any]) -> None:
    """Send one message; raises ``OSError`` once the runner is gone."""
    sock.sendall(json.dumps(msg).encode() + b"\n")


def _reap(sock: socket.socket, children: set[int]) -> None:
    """Reap every ended child, kill the strays of its group, report its status and rusage."""
    while children:
        try:
            pid, status, ru = os.wait4(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        children.discard(pid)
        kill_group(pid)
        report = {"exit": pid, "status": status, "utime": ru.ru_utime, "stime": ru.ru_stime}
        _send(sock, {**report, "maxrss": ru.ru_maxrss})


def serve(fd: int) -> None:
    """The server's loop on socket ``fd``: fork on request, report the ends; exits on EOF."""
    sock = socket.socket(fileno=fd)
    set_process_name(SERVER_NAME)
    failed = _preload()
    _reset_signals()  # PETSc's handlers would turn a broken pipe into an MPI_Abort
    # Python >= 3.12 warns at each fork of a process with threads; the ones here are MPI's,
    # OpenBLAS' and jemalloc's, which keep no lock a child needs across the fork (OpenBLAS and
    # jemalloc have fork handlers), and a test forks a real solve to show the child works.
    warnings.filterwarnings("ignore", ".*fork.*", DeprecationWarning)
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_r, False)
    os.set_blocking(wake_w, False)
    signal.set_wakeup_fd(wake_w)
    signal.signal(signal.SIGCHLD, lambda signum, frame: None)  # wakes the select
    me, fds = os.getpid(), (fd, wake_r, wake_w)
    children: set[int] = set()
    buf = b""
    try:
        _send(sock, {"ready": True, "pid": me, "preload_failed": failed})
        while True:
            # A socket and an fd, both FileDescriptorLike (mypy joins the list to object).
            ready = select.select([sock, wake_r], [], [])[0]  # type: ignore[type-var]
            if wake_r in ready:
                while True:
                    try:
                        if not os.read(wake_r, 512):
                            break
                    except BlockingIOError:
                        break
            _reap(sock, children)
            if sock not in ready:
                continue
            data = sock.recv(1 << 16)
            if not data:
                return
            *lines, buf = (buf + data).split(b"\n")
            for line in lines:
                req = json.loads(line)
                sys.stdout.flush()
                sys.stderr.flush()
                try:
                    pid = os.fork()
                except OSError as err:
                    _send(sock, {"id": req["id"], "error": f"fork failed: {err}"})
                    continue
                if pid == 0:
                    _child(req, me, fds)
                children.add(pid)
                _send(sock, {"id": req["id"], "pid": pid})
    except OSError:
        return  # the runner is gone
    finally:
        for pid in children:
            kill_group(pid)


if __name__ == "__main__":
    serve(int(sys.argv[1]))
    os._exit(0)
