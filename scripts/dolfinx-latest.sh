#!/usr/bin/env bash
# Run woundsweep's DOLFINx-dependent tests on the newest Debian DOLFINx (sid: 0.11).
#
#   scripts/dolfinx-latest.sh                  build the sid root if needed, run the fem tests + a demo solve,
#                                              then the same demo job on the host DOLFINx: per-stage max and
#                                              p99 von Mises must agree within 1 % (compare_stage_results.py)
#   scripts/dolfinx-latest.sh --build-only     only build / update the root
#   scripts/dolfinx-latest.sh --shell          interactive shell in the root (source tree at /src)
#   scripts/dolfinx-latest.sh --run CMD ARGS   run one command in the root (e.g. --run python3 scripts/probes/x.py)
#   scripts/dolfinx-latest.sh -- PYTEST_ARGS   extra pytest arguments (e.g. -- -k stages -x)
#
# The root is built once with debootstrap and reused while its stamps match; a half-built root
# (no base stamp) is rebuilt, a root whose package list changed gets the missing packages only.
# The source tree is bind-mounted READ-ONLY at /src and put on PYTHONPATH (so nothing is
# installed into it and a test that writes into the source tree fails here too).
# All mounts live in private mount + PID namespaces (unshare): they and every process of the run
# vanish with it even if it is killed, and a trap unmounts them explicitly on every exit path.
#
# Environment: DOLFINX_LATEST_SUITE (Debian suite, default sid = DOLFINx 0.11; trixie = 0.9),
#   WOUNDSWEEP_SID_ROOT (default /var/cache/woundsweep/SUITE-root),
#   WOUNDSWEEP_SID_MIRROR (default http://deb.debian.org/debian), DOLFINX_LATEST_DEMO=0 skips the
#   demo solve, DOLFINX_LATEST_VERIFY=0 skips `woundsweep verify --quick`,
#   DOLFINX_LATEST_MARKERS (pytest -m expression, default "fem";
#   tests/execution/test_slurm.py and tests/execution/test_slurm_cluster.py are always left
#   out: they need SLURM on the host),
#   DOLFINX_LATEST_TIMEOUT (seconds for the whole in-root run, default 1500),
#   DOLFINX_LATEST_OUT (host directory for the demo job's results, default a new /tmp directory).
# Exit status: the tests' status (0 pass, 1 failures, ...); 77 = cannot run here (not root,
#   no debootstrap/chroot/unshare, no mount permission), with one line on stderr saying why;
#   78 = building the root failed (log kept beside the root).
set -euo pipefail

SKIP=77
BUILD_FAILED=78
SRC=$(cd "$(dirname "$0")/.." && pwd)
SUITE=${DOLFINX_LATEST_SUITE:-sid}
ROOT=${WOUNDSWEEP_SID_ROOT:-/var/cache/woundsweep/$SUITE-root}
MIRROR=${WOUNDSWEEP_SID_MIRROR:-http://deb.debian.org/debian}
LOCK="$ROOT.lock"
BASE_STAMP="$ROOT/.woundsweep-base-ok"
PKG_STAMP="$ROOT/.woundsweep-packages"
BUILD_LOG="$ROOT.build.log"
APT_OPTS=(-o Acquire::Check-Valid-Until=false -o APT::Install-Recommends=false -o Dpkg::Use-Pty=0)
# What woundsweep imports (pyproject dependencies) + DOLFINx + the test runner. Every one is a
# Debian package in sid, xgboost included (python3-xgboost), so nothing comes from pip.
# Optional ones come from Debian where the suite has them, else as binary wheels from PyPI
# (pip --only-binary, --break-system-packages inside the throw-away root): trixie has neither
# python3-pyarrow nor python3-xgboost.
PACKAGES=(python3-dolfinx-real python3-numpy python3-pandas
          python3-h5py python3-yaml python3-click python3-tqdm python3-matplotlib python3-sklearn
          python3-scipy python3-pytest python3-pytest-timeout python3-pytest-xdist
          libopenblas0-serial ca-certificates python3-pip
          libgl1 libglu1-mesa libxcursor1 libxinerama1 libxft2 libxrender1)
OPTIONAL_PACKAGES=(python3-pyarrow python3-xgboost)
# The gmsh wheel dlopens libGL.so.1 and friends: libgl1 is named itself because sid's
# libglu1-mesa no longer pulls it in. gmsh comes from PyPI as on the host (Debian's
# python3-gmsh lacks the Netgen optimiser that woundsweep.mesh enables), at the host
# venv's version so both DOLFINx versions solve the same mesh (geometry.build_mesh is
# deterministic for one gmsh version).
host_gmsh=$("$SRC/.venv/bin/python" -c 'import gmsh; print(gmsh.__version__)' 2>/dev/null || true)
WHEELS=("gmsh${host_gmsh:+==$host_gmsh}")

say() { echo "dolfinx-latest: $*" >&2; }
skip() { say "skipped: $*"; exit "$SKIP"; }
elapsed() { echo $(($(date +%s) - $1)); }

mode="test"
cmd=()
pytest_extra=()
while (($#)); do
    case "$1" in
        --build-only) mode=build ;;
        --shell) mode=shell ;;
        --run) mode=run; shift; cmd=("$@"); break ;;
        --) shift; pytest_extra=("$@"); break ;;
        -h|--help) sed -n '2,27p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) say "unknown argument: $1 (see --help)"; exit 2 ;;
    esac
    shift
done

# ---- can we run at all? (one line, distinct status, so CI can tell "skipped" from "failed")
[[ $(id -u) -eq 0 ]] || skip "needs root (debootstrap, chroot and bind mounts)"
for tool in chroot unshare setpriv flock mount umount timeout; do
    command -v "$tool" >/dev/null 2>&1 || skip "no $tool on PATH"
done
if [[ ! -f "$BASE_STAMP" ]] && ! command -v debootstrap >/dev/null 2>&1; then
    if command -v apt-get >/dev/null 2>&1; then
        say "installing debootstrap"
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null 2>&1 ||
            { apt-get update -qq >/dev/null 2>&1 &&
              DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null 2>&1; } || true
    fi
    command -v debootstrap >/dev/null 2>&1 || skip "no debootstrap and no ready root at $ROOT"
fi
unshare --mount --pid --fork --propagation private true 2>/dev/null ||
    skip "cannot create mount + PID namespaces (unshare --mount --pid) here"

mkdir -p "$(dirname "$ROOT")"
exec 9>"$LOCK"
flock -w 1800 9 || { say "another run holds $LOCK"; exit 1; }

# Paths mounted below ROOT right now (as seen from the host namespace).
mounts_under_root() { awk -v r="$ROOT/" 'index($2 "/", r) == 1 {print $2}' /proc/mounts; }

# ---- build / update the root
build_root() {
    local t0
    t0=$(date +%s)
    if [[ -n "$(mounts_under_root)" ]]; then
        say "refusing to rebuild: mounts still under $ROOT:"; mounts_under_root >&2; exit "$BUILD_FAILED"
    fi
    say "building Debian $SUITE root at $ROOT (about 2-3 minutes; log: $BUILD_LOG)"
    rm -rf --one-file-system "$ROOT"
    : >"$BUILD_LOG"
    if ! debootstrap --variant=minbase "$SUITE" "$ROOT" "$MIRROR" >>"$BUILD_LOG" 2>&1; then
        tail -n 15 "$BUILD_LOG" >&2; say "debootstrap failed"; exit "$BUILD_FAILED"
    fi
    touch "$BASE_STAMP"
    say "base system in $(elapsed "$t0") s"
}

install_packages() {
    local t0 want
    t0=$(date +%s)
    want=$(printf '%s\n' "${PACKAGES[@]}" "${OPTIONAL_PACKAGES[@]}" "${WHEELS[@]}" | sha256sum | cut -c1-16)
    [[ -f "$PKG_STAMP" && "$(cat "$PKG_STAMP")" == "$want" ]] && return 0
    say "installing ${#PACKAGES[@]} packages into the root (log: $BUILD_LOG)"
    cp -L /etc/resolv.conf "$ROOT/etc/resolv.conf"
    # pip in the root trusts what pip on the host trusts (e.g. a site proxy's CA bundle).
    local ca=${PIP_CERT:-${SSL_CERT_FILE:-}}
    rm -f "$ROOT/etc/ssl/host-ca-bundle.crt"
    # A fresh minbase root may have no /etc/ssl yet (sid: ca-certificates is not in minbase).
    if [[ -n $ca && -f $ca ]]; then
        mkdir -p "$ROOT/etc/ssl"
        cp -L "$ca" "$ROOT/etc/ssl/host-ca-bundle.crt"
    fi
    # apt/dpkg need /proc and /dev/null; mount them privately for just this step.
    # shellcheck disable=SC2016  # the script is expanded by the inner bash
    if ! PKGS="${PACKAGES[*]}" OPT_PKGS="${OPTIONAL_PACKAGES[*]}" WHEELS="${WHEELS[*]}" unshare -m --propagation private bash -c '
            set -e
            root=$1; shift
            mount -t proc proc "$root/proc"
            mount --bind /dev "$root/dev"
            export DEBIAN_FRONTEND=noninteractive LC_ALL=C.UTF-8
            chroot "$root" dpkg --configure -a  # finish an install that was interrupted
            chroot "$root" apt-get "$@" -q update
            optional=()
            read -r -a wheels <<<"$WHEELS"
            for p in $OPT_PKGS; do
                if chroot "$root" apt-cache show "$p" >/dev/null 2>&1; then optional+=("$p"); else wheels+=("${p#python3-}"); fi
            done
            chroot "$root" apt-get "$@" -y -q install $PKGS "${optional[@]}"
            # The Debian gmsh (no Netgen) must not shadow the wheel: pip would take it as installed.
            if chroot "$root" dpkg-query -W python3-gmsh >/dev/null 2>&1; then
                chroot "$root" apt-get "$@" -y -q purge python3-gmsh
            fi
            if ((${#wheels[@]})); then
                echo "installing wheels: ${wheels[*]}"
                cert=()
                [[ -f $root/etc/ssl/host-ca-bundle.crt ]] && cert=(--cert /etc/ssl/host-ca-bundle.crt)
                # Host paths in PIP_*/SSL_* variables mean nothing inside the root: clear them.
                env -u PIP_FIND_LINKS -u PIP_CERT -u SSL_CERT_FILE -u REQUESTS_CA_BUNDLE -u CURL_CA_BUNDLE \
                    chroot "$root" python3 -m pip install -q --break-system-packages \
                    --only-binary=:all: "${cert[@]}" "${wheels[@]}"
            fi
            # A missing shared library of the gmsh wheel fails here, with its name in the log.
            chroot "$root" python3 -c "import gmsh"
            chroot "$root" apt-get clean
        ' _ "$ROOT" "${APT_OPTS[@]}" >>"$BUILD_LOG" 2>&1; then
        tail -n 20 "$BUILD_LOG" >&2; say "apt-get in the root failed"; exit "$BUILD_FAILED"
    fi
    # Prefer the serial OpenBLAS for MUMPS (3.5x faster than reference BLAS, no thread fights).
    for alt in libblas.so.3-x86_64-linux-gnu liblapack.so.3-x86_64-linux-gnu; do
        target=$(chroot "$ROOT" update-alternatives --list "$alt" 2>/dev/null | grep openblas-serial || true)
        [[ -z "$target" ]] || chroot "$ROOT" update-alternatives --set "$alt" "$target" >/dev/null 2>&1 || true
    done
    # `woundsweep` on PATH inside the root, running the bind-mounted source tree.
    printf '#!/bin/sh\nexec python3 -m woundsweep "$@"\n' >"$ROOT/usr/local/bin/woundsweep"
    chmod 755 "$ROOT/usr/local/bin/woundsweep"
    mkdir -p "$ROOT/src"
    echo "$want" >"$PKG_STAMP"
    say "packages in $(elapsed "$t0") s"
}

[[ -f "$BASE_STAMP" ]] || build_root
install_packages
if [[ $mode == build ]]; then
    say "root ready: python3-dolfinx-real $(chroot "$ROOT" dpkg-query -W -f="\${Version}" python3-dolfinx-real)"
    exit 0
fi

# ---- what runs inside the root (mode "test"): fem tests, then one demo job through all stages
# "A-B" covering every stage of the model.
STAGES_PY='from woundsweep.core.schema import STAGES as s; print(f"{min(s)}-{max(s)}")'
in_root=$(cat <<'IN_ROOT'
set -uo pipefail
cd /src
STAGES_PY=$1; shift
python3 -c 'import dolfinx, sys, numpy; print(f"dolfinx-latest: DOLFINx {dolfinx.__version__}, Python {sys.version.split()[0]}, numpy {numpy.__version__}")'
t0=$(date +%s)
rc=0
# -p no:cacheprovider: /src is read-only; -n auto: one pytest-xdist worker per core, whole
# files per worker (as `make test`). Every fem test (the rest runs on the host already)
# except the SLURM ones, which need slurmctld/slurmd on the host (the root has no cluster) and
# test the scheduling around `woundsweep solve`, not DOLFINx; they run on the host's DOLFINx.
markers=${DOLFINX_LATEST_MARKERS:-fem}
echo "dolfinx-latest: pytest -m '$markers' --ignore=tests/execution/test_slurm.py --ignore=tests/execution/test_slurm_cluster.py $*"
python3 -m pytest -m "$markers" --ignore=tests/execution/test_slurm.py --ignore=tests/execution/test_slurm_cluster.py -p no:cacheprovider -q -rfE -n auto --dist loadfile "$@" \
    || rc=$?
[[ $rc -eq 5 ]] && { echo "dolfinx-latest: no fem tests collected"; rc=0; }
echo "dolfinx-latest: fem tests: $(($(date +%s) - t0)) s, status $rc"
# The verification cases' quick subset on this DOLFINx (docs/validation.md, "Verification"):
# a DOLFINx that changes the physics fails here with the case that moved.
if [[ ${DOLFINX_LATEST_VERIFY:-1} != 0 ]]; then
    t0=$(date +%s)
    vrc=0
    woundsweep verify --quick || vrc=$?
    echo "dolfinx-latest: verify --quick: $(($(date +%s) - t0)) s, status $vrc"
    ((rc == 0 && vrc != 0)) && rc=$vrc
fi
if [[ ${DOLFINX_LATEST_DEMO:-1} != 0 ]]; then
    STAGES=$(python3 -c "$STAGES_PY" 2>/dev/null || echo 1-6)
    t0=$(date +%s)
    drc=0
    woundsweep generate sweeps/demo.yaml --out /out/run-latest >/dev/null &&
        woundsweep solve /out/run-latest --job 0 --stages "$STAGES" --out /out/job0-latest.h5 || drc=$?
    echo "dolfinx-latest: demo solve (job 0, stages $STAGES): $(($(date +%s) - t0)) s, status $drc"
    ((rc == 0 && drc != 0)) && rc=$drc
fi
exit $rc
IN_ROOT
)

# ---- run inside private mount + PID namespaces
# The inner script is PID 1 of a new PID namespace with its own mount namespace: it mounts,
# runs, and unmounts in reverse order on every exit path (trap). Even on SIGKILL nothing can
# leak: the mounts were never visible to the host, and when PID 1 dies the kernel kills every
# process of the run (MPI helpers included). setpriv --pdeathsig ties the namespace to this
# script, so killing the script kills the run.
inner=$(cat <<'INNER'
set -uo pipefail
ROOT=$1; SRC=$2; OUT=$3; mode=$4; in_root=$5; limit=$6; STAGES_PY=$7; shift 7
mounted=()
cleanup() {
    local i
    for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do
        umount "${mounted[i]}" 2>/dev/null || umount -l "${mounted[i]}" 2>/dev/null || true
    done
}
trap cleanup EXIT
trap 'exit 130' INT TERM
m() { mount "$@" && mounted+=("${@: -1}"); }
mkdir -p "$ROOT/src" "$ROOT/out"
m -t proc proc "$ROOT/proc" || exit 77
m -t sysfs sys "$ROOT/sys" || exit 77
m --bind /dev "$ROOT/dev" || exit 77
m -t devpts -o newinstance,ptmxmode=0666 devpts "$ROOT/dev/pts" || true
m -t tmpfs -o mode=1777,size=2g shm "$ROOT/dev/shm" || exit 77
m -t tmpfs -o mode=1777 tmp "$ROOT/tmp" || exit 77
m --bind "$SRC" "$ROOT/src" || exit 77
mount -o remount,bind,ro "$ROOT/src" || exit 77
m --bind "$OUT" "$ROOT/out" || exit 77
# A clean environment: host paths (PIP_*, SSL_CERT_FILE, PYTHON*, venvs) mean nothing in the
# root. Passed through: CI and the project's own WOUNDSWEEP_* / DOLFINX_LATEST_* switches.
envv=(HOME=/root LC_ALL=C.UTF-8 TERM="${TERM:-dumb}" PYTHONPATH=/src PYTHONDONTWRITEBYTECODE=1
      PYTHONUNBUFFERED=1 OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
      OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 PATH=/usr/local/bin:/usr/bin:/bin:/usr/sbin:/sbin)
while IFS= read -r name; do
    envv+=("$name=${!name}")
done < <(compgen -e | grep -E '^(CI|WOUNDSWEEP_[A-Z0-9_]+|DOLFINX_LATEST_[A-Z0-9_]+)$' || true)
case $mode in
    shell) env -i "${envv[@]}" chroot "$ROOT" bash -c 'cd /src && exec bash -i' ;;
    run) env -i "${envv[@]}" timeout -k 30 "$limit" chroot "$ROOT" bash -c 'cd /src && exec "$@"' _ "$@" ;;
    *) env -i "${envv[@]}" timeout -k 30 "$limit" chroot "$ROOT" bash -c "$in_root" _ "$STAGES_PY" "$@" ;;
esac
INNER
)

case $mode in
    shell) args=() ;;
    run) args=("${cmd[@]}") ;;
    *) args=(${pytest_extra[@]+"${pytest_extra[@]}"}) ;;
esac
# Results of the in-root run (demo job output) land here, on the host.
OUT=${DOLFINX_LATEST_OUT:-$(mktemp -d /tmp/woundsweep-dolfinx-latest.XXXXXX)}
mkdir -p "$OUT"
t0=$(date +%s)
rc=0
limit=${DOLFINX_LATEST_TIMEOUT:-1500}
setpriv --pdeathsig KILL unshare --mount --pid --fork --kill-child --propagation private \
    bash -c "$inner" _ "$ROOT" "$SRC" "$OUT" "$mode" "$in_root" "$limit" "$STAGES_PY" \
    ${args[@]+"${args[@]}"} || rc=$?
# Belt and braces: nothing may be left mounted under the root in the host namespace.
if [[ -n "$(mounts_under_root)" ]]; then
    say "WARNING: mounts left under $ROOT:"; mounts_under_root >&2
fi
[[ $rc -eq 124 ]] && say "timed out after $limit s"
say "in-root run: $(elapsed "$t0") s, status $rc"

# ---- same demo job on the host's DOLFINx: per-stage maximal stress must agree within 1 %
if [[ $mode == test && -f "$OUT/job0-latest.h5" && -x "$SRC/.venv/bin/woundsweep" ]]; then
    t0=$(date +%s)
    hrc=0
    # The stage range the root solved (the host runs the same source tree).
    STAGES=$("$SRC/.venv/bin/python" -c "$STAGES_PY" 2>/dev/null || echo 1-6)
    "$SRC/.venv/bin/woundsweep" generate "$SRC/sweeps/demo.yaml" --out "$OUT/run-host" >/dev/null &&
        "$SRC/.venv/bin/woundsweep" solve "$OUT/run-host" --job 0 --stages "$STAGES" --out "$OUT/job0-host.h5" || hrc=$?
    say "host demo solve: $(elapsed "$t0") s, status $hrc"
    if ((hrc == 0)); then
        "$SRC/.venv/bin/python" "$SRC/scripts/probes/compare_stage_results.py" \
            "$OUT/job0-host.h5" "$OUT/job0-latest.h5" --rtol 0.01 || hrc=$?
    fi
    ((rc == 0 && hrc != 0)) && rc=$hrc
fi
if rmdir "$OUT" 2>/dev/null; then :; else say "results in $OUT"; fi
exit "$rc"
