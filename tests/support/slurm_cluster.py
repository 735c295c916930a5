"""A real one-node SLURM cluster on this machine, for end-to-end tests.

`start_cluster(root)` writes a private configuration under ``root`` (munge key and socket,
slurm.conf, state, spool and log directories, free TCP ports), starts ``munged``, ``slurmctld``
and ``slurmd`` in the foreground as child processes, and waits until the node is idle.
`SlurmCluster.stop()` cancels the cluster's jobs, waits for them to end and stops the daemons
by the pids this module started (never by name). Nothing outside ``root`` is configured: the
client commands find the cluster through ``SLURM_CONF`` in `SlurmCluster.env`.

Configuration: ``ProctrackType=proctrack/linuxproc``, ``TaskPlugin=task/none``,
``SelectType=select/cons_tres``; the node is named after the host with its CPU count and a
RealMemory a bit below the memory available now.
`unavailable_reason()` says why a cluster cannot be started here (not Linux, Debian's
``slurm-wlm`` and ``munge`` not installed, not root), for ``pytest.skip``. The tests never
install anything: scripts/test-deps.sh (`make test-deps`, run by `make test`) does.
"""

from __future__ import annotations

import ctypes
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "DAEMONS",
    "PACKAGES",
    "ClusterError",
    "SlurmCluster",
    "parse_parsable",
    "start_cluster",
    "unavailable_reason",
]

PACKAGES = ("slurm-wlm", "munge")
# Programs the cluster needs: daemons and the client commands the tests call.
DAEMONS = ("munged", "munge", "slurmctld", "slurmd", "sbatch", "squeue", "sinfo", "scontrol")
_SBIN = ("/usr/sbin", "/sbin", "/usr/bin", "/bin")


class ClusterError(RuntimeError):
    """The cluster could not be started or stopped; the message quotes the daemon logs."""


def _which(name: str) -> str | None:
    # Root's PATH normally has sbin, a test runner's may not.
    path = os.environ.get("PATH", "") + os.pathsep + os.pathsep.join(_SBIN)
    return shutil.which(name, path=path)


def _missing() -> list[str]:
    return [d for d in DAEMONS if _which(d) is None]


def unavailable_reason() -> str | None:
    """Why no cluster can run here, or None."""
    if not sys.platform.startswith("linux"):
        return f"a SLURM cluster needs Linux (this is {sys.platform})"
    if _missing():
        return (
            f"SLURM/munge programs missing ({', '.join(_missing())}): run `make test-deps` "
            f"(scripts/test-deps.sh installs Debian's {' and '.join(PACKAGES)})"
        )
    if os.geteuid() != 0:
        return "starting a SLURM cluster (slurmd, munged) needs root; not root here"
    return None


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _mem_available_mb() -> int:
    with open("/proc/meminfo") as fh:
        info = {line.split(":")[0]: int(line.split()[1]) for line in fh if line.strip()}
    return int(info.get("MemAvailable", info["MemTotal"]) // 1024)


def slurm_conf(root: Path, host: str, cpus: int, mem_mb: int, ports: tuple[int, int]) -> str:
    """The slurm.conf of a private one-node cluster whose files all live under ``root``."""
    return f"""\
# One-node test cluster: every path under {root}.
ClusterName=wstest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ports[0]}
SlurmdPort={ports[1]}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={root}/munge/munge.sock
StateSaveLocation={root}/state
SlurmdSpoolDir={root}/spool
SlurmctldPidFile={root}/run/slurmctld.pid
SlurmdPidFile={root}/run/slurmd.pid
SlurmctldLogFile={root}/log/slurmctld.log
SlurmdLogFile={root}/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
PlugStackConfig={root}/plugstack.conf
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
MpiDefault=none
SwitchType=switch/none
ReturnToService=2
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc={root}/log/jobcomp.txt
# Keep finished jobs visible to `scontrol show job` for the whole test.
MinJobAge=3600
SlurmctldTimeout=30
SlurmdTimeout=60
NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={mem_mb} State=UNKNOWN
PartitionName=debug Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


@dataclass
class SlurmCluster:
    """A running cluster: its directory, configuration and the daemons this process started."""

    root: Path
    conf: Path
    node: str
    cpus: int
    env: dict[str, str]
    procs: dict[str, subprocess.Popen] = field(default_factory=dict)

    def run(self, *args: str, check: bool = True, timeout: float = 60) -> str:
        """Run a SLURM client command against this cluster; return its stdout."""
        exe = _which(args[0]) or args[0]
        res = subprocess.run(
            [exe, *args[1:]], env=self.env, capture_output=True, text=True, timeout=timeout
        )
        if check and res.returncode != 0:
            raise ClusterError(f"{' '.join(args)}: exit {res.returncode}: {res.stderr.strip()}")
        return res.stdout

    def node_state(self) -> str:
        return self.run("sinfo", "-h", "-N", "-o", "%t", check=False).strip()

    def queued(self) -> list[str]:
        """Ids (``123`` or ``123_4``) of the jobs still pending or running."""
        return self.run("squeue", "-h", "-o", "%i").split()

    def job(self, job_id: str) -> dict[str, str]:
        """``scontrol show job`` as a dict (first record; for an array, pass ``id_task``)."""
        out = self.run("scontrol", "-o", "show", "job", job_id)
        first = out.splitlines()[0]
        return dict(kv.split("=", 1) for kv in first.split() if "=" in kv)

    def array_tasks(self, array_id: str) -> list[dict[str, str]]:
        """One ``scontrol show job`` record per task of array job ``array_id``."""
        out = self.run("scontrol", "-o", "show", "job", array_id)
        return [dict(kv.split("=", 1) for kv in ln.split() if "=" in kv) for ln in out.splitlines()]

    def wait_until_empty(self, timeout: float, poll: float = 2.0) -> None:
        """Wait until no job is pending or running; ClusterError after ``timeout`` seconds."""
        end = time.monotonic() + timeout
        while True:
            left = self.queued()
            if not left:
                return
            if time.monotonic() > end:
                raise ClusterError(
                    f"jobs still queued after {timeout:.0f} s: {left}\n{self.run('squeue')}"
                )
            time.sleep(poll)

    def logs(self, tail: int = 30) -> str:
        """The last lines of the daemons' logs, for failure messages."""
        parts = []
        for name in ("slurmctld.log", "slurmd.log", "munged.log"):
            p = self.root / "log" / name
            if p.is_file():
                lines = p.read_text(errors="replace").splitlines()[-tail:]
                parts.append(f"--- {name}\n" + "\n".join(lines))
        return "\n".join(parts)

    def _stepds(self) -> list[int]:
        # slurmstepd processes forked by *our* slurmd: they inherit its SLURM_CONF.
        mark = f"SLURM_CONF={self.conf}".encode()
        found = []
        for d in Path("/proc").iterdir():
            if not d.name.isdigit():
                continue
            try:
                if (d / "comm").read_text().strip() != "slurmstepd":
                    continue
                if mark in (d / "environ").read_bytes().split(b"\0"):
                    found.append(int(d.name))
            except OSError:
                continue
        return found

    def stop(self, timeout: float = 30) -> None:
        """Cancel the jobs, wait for them, then stop slurmd, slurmctld and munged by pid."""
        if self.procs.get("slurmctld") and self.procs["slurmctld"].poll() is None:
            try:
                if self.queued():
                    self.run("scancel", "--full", "--user", "root", check=False)
                    self.wait_until_empty(timeout, poll=0.5)
            except (ClusterError, subprocess.TimeoutExpired, OSError):
                pass  # the daemons are stopped below whatever the queue says
        for name in ("slurmd", "slurmctld", "munged"):
            proc = self.procs.pop(name, None)
            if proc is None or proc.poll() is not None:
                continue
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=15)
        for pid in self._stepds():  # steps that outlived their slurmd
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def __enter__(self) -> SlurmCluster:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _die_with_parent() -> None:
    # PR_SET_PDEATHSIG: a test process killed with -9 takes its daemons with it.
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)


def _start(
    cluster: SlurmCluster, name: str, argv: Sequence[str], log: Path, env: dict[str, str]
) -> None:
    exe = _which(argv[0])
    if exe is None:
        raise ClusterError(f"{argv[0]}: not installed")
    with open(log, "ab") as fh:
        cluster.procs[name] = subprocess.Popen(
            [exe, *argv[1:]], stdout=fh, stderr=subprocess.STDOUT, env=env,
            start_new_session=True,  # a Ctrl-C in the test's terminal is not theirs
            preexec_fn=_die_with_parent,
        )  # fmt: skip


def _wait(cluster: SlurmCluster, what: str, ready, timeout: float) -> None:
    end = time.monotonic() + timeout
    while not ready():
        dead = [n for n, p in cluster.procs.items() if p.poll() is not None]
        if dead:
            raise ClusterError(
                f"{', '.join(dead)} exited while waiting for {what}\n{cluster.logs()}"
            )
        if time.monotonic() > end:
            raise ClusterError(
                f"timed out after {timeout:.0f} s waiting for {what}\n{cluster.logs()}"
            )
        time.sleep(0.3)


def start_cluster(root: str | Path, timeout: float = 90) -> SlurmCluster:
    """Start munged, slurmctld and slurmd under ``root``; return once the node is idle.

    On any failure the daemons already started are stopped before the error propagates.
    """
    root = Path(root).resolve()
    for sub in ("munge", "state", "spool", "run", "log"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    # munged insists: socket directory searchable by all, key readable by its owner only.
    for d in (root, root / "munge"):
        os.chmod(d, 0o755)
    key = root / "munge" / "munge.key"
    key.write_bytes(os.urandom(1024))
    os.chmod(key, 0o600)
    (root / "plugstack.conf").write_text("")
    host = socket.gethostname().split(".")[0]
    cpus = os.cpu_count() or 1
    mem_mb = max(256, int(_mem_available_mb() * 0.9))
    conf = root / "slurm.conf"
    conf.write_text(slurm_conf(root, host, cpus, mem_mb, (_free_port(), _free_port())))
    env = dict(os.environ, SLURM_CONF=str(conf))
    for var in [v for v in env if v.startswith(("SLURM_", "SBATCH_", "SQUEUE_"))]:
        if var != "SLURM_CONF":  # a test run inside a SLURM job must not leak its job's settings
            del env[var]
    cluster = SlurmCluster(root=root, conf=conf, node=host, cpus=cpus, env=env)
    sock = root / "munge" / "munge.sock"
    try:
        _start(
            cluster, "munged",
            ["munged", "-F", f"--key-file={key}", f"--socket={sock}",
             f"--pid-file={root / 'run' / 'munged.pid'}", f"--seed-file={root / 'munge' / 'seed'}",
             f"--log-file={root / 'log' / 'munged.log'}"],
            root / "log" / "munged.log", env,
        )  # fmt: skip
        _wait(cluster, "munged's socket", sock.exists, timeout)
        _start(cluster, "slurmctld", ["slurmctld", "-D", "-i", "-f", str(conf)],
               root / "log" / "slurmctld.out", env)  # fmt: skip
        _wait(cluster, "slurmctld", lambda: cluster.run("scontrol", "ping", check=False)
              .find("UP") >= 0, timeout)  # fmt: skip
        _start(cluster, "slurmd", ["slurmd", "-D", "-f", str(conf)],
               root / "log" / "slurmd.out", env)  # fmt: skip
        _wait(cluster, "the node to be idle", lambda: cluster.node_state() == "idle", timeout)
    except BaseException:
        cluster.stop()
        raise
    return cluster


def parse_parsable(out: str) -> str:
    """The job id from ``sbatch --parsable`` output (``id`` or ``id;cluster``)."""
    m = re.match(r"\s*(\d+)", out)
    if not m:
        raise ClusterError(f"sbatch --parsable printed no job id: {out!r}")
    return m.group(1)
