#!/usr/bin/env bash
# Idempotent setup for a Debian 12 machine (run as root, or with sudo available).
# h5py must be Debian's (same libhdf5 as DOLFINx; the PyPI wheel breaks after `import dolfinx`).
# Installs the Debian packages woundsweep needs (DOLFINx 0.5.2 from bookworm),
# creates .venv on the system interpreter with --system-site-packages, and
# installs woundsweep into it with the pins that keep Debian's DOLFINx working.
set -euo pipefail
cd "$(dirname "$0")/.."

APT_PACKAGES=(python3-dolfinx-real python3-h5py libopenblas0-serial python3-venv python3-pip
              libglu1-mesa libxcursor1 libxinerama1 libxft2 libxrender1)
VENV=.venv
STAMP="$VENV/.woundsweep-setup"

if ! command -v apt-get >/dev/null 2>&1 || ! command -v dpkg-query >/dev/null 2>&1; then
    echo "setup: no apt-get here; create the conda environment instead: conda env create -f environment.yml" >&2
    exit 1
fi

missing=()
for p in "${APT_PACKAGES[@]}"; do
    status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
    [[ "$status" == "install ok installed" ]] || missing+=("$p")
done
if ((${#missing[@]})); then
    SUDO=""
    [[ $(id -u) -eq 0 ]] || SUDO="sudo"
    echo "setup: installing Debian packages: ${missing[*]}"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# The reference BLAS is ~3.5x slower in MUMPS; prefer the serial OpenBLAS.
if command -v update-alternatives >/dev/null 2>&1; then
    for alt in libblas.so.3-x86_64-linux-gnu liblapack.so.3-x86_64-linux-gnu; do
        target=$(update-alternatives --list "$alt" 2>/dev/null | grep openblas-serial || true)
        if [[ -n "$target" ]] && [[ "$(readlink -f /etc/alternatives/$alt)" != "$(readlink -f "$target")" ]]; then
            update-alternatives --set "$alt" "$target" >/dev/null 2>&1 || true
        fi
    done
fi

want=$(cat pyproject.toml scripts/setup.sh | sha256sum | cut -c1-16)
if [[ -f "$STAMP" && "$(cat "$STAMP")" == "$want" && -x "$VENV/bin/woundsweep" ]]; then
    exit 0
fi
if [[ ! -x "$VENV/bin/python" ]]; then
    echo "setup: creating $VENV (system Python with --system-site-packages)"
    /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi
echo "setup: installing woundsweep into $VENV"
log="$VENV/pip-install.log"
if ! { "$VENV/bin/python" -m pip install -q --upgrade "pip>=23" &&
       "$VENV/bin/python" -m pip install -q "numpy<2" "pyarrow<21" -e ".[test]"; } >"$log" 2>&1; then
    tail -n 20 "$log" >&2
    echo "setup: pip install failed (full log: $log)" >&2
    exit 1
fi
"$VENV/bin/python" -c "import dolfinx, gmsh, xgboost, pyarrow, h5py; print('setup: dolfinx', dolfinx.__version__, 'gmsh', gmsh.__version__)"
echo "$want" > "$STAMP"
