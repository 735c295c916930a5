#!/usr/bin/env bash
# Idempotent install of the Debian packages the tests marked `system` need (Debian 12, as root
# or with sudo; `make test` runs it through `make test-deps`):
#   slurm-wlm, munge          a private one-node SLURM (tests/execution/test_slurm_cluster.py)
#   chromium, chromium-driver headless Chromium for selenium (tests/viz/test_viz_browser.py)
# Installs only what is missing: with everything present it does nothing (no apt-get call).
# Without them, pytest run directly skips those tests with a reason naming `make test-deps`.
# Failure is one line on stderr and exit 1.
set -euo pipefail

# Installed as the tests did before: SLURM with its recommended plugins, Chromium without
# recommends.
WITH_RECOMMENDS=(slurm-wlm munge)
NO_RECOMMENDS=(chromium chromium-driver)

fail() {
    echo "test-deps: $*" >&2
    exit 1
}

missing_of() {
    local p status
    for p in "$@"; do
        status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
        [[ "$status" == "install ok installed" ]] || echo "$p"
    done
}

if ! command -v apt-get >/dev/null 2>&1 || ! command -v dpkg-query >/dev/null 2>&1; then
    fail "no apt-get/dpkg here to install ${WITH_RECOMMENDS[*]} ${NO_RECOMMENDS[*]}; install them by hand (pytest skips the tests marked system without them)"
fi

mapfile -t missing_rec < <(missing_of "${WITH_RECOMMENDS[@]}")
mapfile -t missing_norec < <(missing_of "${NO_RECOMMENDS[@]}")
missing=("${missing_rec[@]}" "${missing_norec[@]}")
((${#missing[@]})) || exit 0

SUDO=()
if [[ $(id -u) -ne 0 ]]; then
    command -v sudo >/dev/null 2>&1 ||
        fail "installing ${missing[*]} needs root (or sudo); not root and no sudo here"
    SUDO=(sudo)
fi

echo "test-deps: installing Debian packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
LOG=$(mktemp)
trap 'rm -f "$LOG"' EXIT
apt_install() {
    "${SUDO[@]}" apt-get -o DPkg::Lock::Timeout=300 install -y -q "$@" >>"$LOG" 2>&1
}
install_missing() {
    ((${#missing_rec[@]} == 0)) || apt_install "${missing_rec[@]}" || return 1
    ((${#missing_norec[@]} == 0)) || apt_install --no-install-recommends "${missing_norec[@]}" || return 1
}
# A stale package list is the usual cause of a failure on a fresh machine: update once, retry.
if ! install_missing; then
    "${SUDO[@]}" apt-get -o DPkg::Lock::Timeout=300 update -q >>"$LOG" 2>&1 || true
    install_missing ||
        fail "apt-get install ${missing[*]} failed: $(grep -E '^(E|Err):' "$LOG" | tail -n 1 || tail -n 1 "$LOG")"
fi

mapfile -t still < <(missing_of "${WITH_RECOMMENDS[@]}" "${NO_RECOMMENDS[@]}")
((${#still[@]} == 0)) || fail "still missing after apt-get install: ${still[*]}"
echo "test-deps: installed"
