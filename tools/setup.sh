#!/usr/bin/env bash
# Installs what dktlbm needs and builds it (release preset: build/dktlbm).
#
#   tools/setup.sh
#
# - Debian/Ubuntu packages: gfortran, Open MPI, parallel HDF5 (Open MPI flavour), hdf5-tools,
#   cmake, ninja, python3, pip. Missing ones are installed with apt-get when run as root;
#   otherwise the exact command is printed and the script exits 1.
# - Python modules for the post-processing and the tests (numpy h5py matplotlib pytest
#   fprettify ruff), for the python3 on PATH; installed with pip when run as root or when that
#   Python's site-packages is writable (venv, pyenv, conda); otherwise the command is printed.
# - The dktlbm Python package (postproc/dktlbm: `import dktlbm`, the dkt-* commands), installed
#   editable (pip install -e) for the same python3, under the same conditions.
# - Then configures (once) and builds the release preset.
# Quiet when everything is there already; safe to run again.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

apt_packages=(gfortran libopenmpi-dev openmpi-bin libhdf5-openmpi-dev hdf5-tools cmake ninja-build
  python3 python3-pip python3-venv)
python_modules=(numpy h5py matplotlib pytest fprettify ruff)

say() { printf 'setup: %s\n' "$*"; }
is_root() { [ "$(id -u)" -eq 0 ]; }

log=$(mktemp "${TMPDIR:-/tmp}/dktlbm-setup.XXXXXX")
trap 'rm -f "$log"' EXIT
# Runs a command with its output in $log; prints the log and stops if it fails.
quietly() {
  if ! "$@" >"$log" 2>&1; then
    cat "$log" >&2
    say "failed: $*" >&2
    exit 1
  fi
}

# ---------------------------------------------------------------- system packages
missing_apt=()
if command -v dpkg-query >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
  for package in "${apt_packages[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q 'install ok installed'; then
      missing_apt+=("$package")
    fi
  done
else
  # Not Debian/Ubuntu (a cluster, another distribution): the tools must be on PATH already,
  # e.g. from `module load` or the system's package manager.
  missing_tools=()
  for tool in "${FC:-gfortran}" mpiexec h5pfc cmake ninja python3; do
    command -v "$tool" >/dev/null 2>&1 || missing_tools+=("$tool")
  done
  if [ ${#missing_tools[@]} -gt 0 ]; then
    say "not found on PATH: ${missing_tools[*]}" >&2
    say "install a Fortran compiler, MPI with mpi_f08, parallel HDF5 with Fortran (h5pfc)," >&2
    say "CMake >= 3.20, Ninja and Python 3 (or load them as modules), then run this again." >&2
    exit 1
  fi
fi

# Modules the python3 on PATH lacks (all of them while there is no python3).
missing_python_modules() {
  missing_py=()
  for module in "${python_modules[@]}"; do
    python3 -c "import $module" >/dev/null 2>&1 || missing_py+=("$module")
  done
}
missing_python_modules

todo=()  # commands a non-root user has to run
if [ ${#missing_apt[@]} -gt 0 ]; then
  if is_root; then
    say "installing ${missing_apt[*]} (apt-get, a few minutes)"
    export DEBIAN_FRONTEND=noninteractive
    quietly apt-get update -q
    quietly apt-get install -y -q --no-install-recommends "${missing_apt[@]}"
    missing_python_modules
  else
    todo+=("sudo apt-get update"
      "sudo apt-get install -y --no-install-recommends ${missing_apt[*]}")
  fi
fi

# ---------------------------------------------------------------- Python modules
# The python3 on PATH is the one the tests and post-processing use (CMake finds the same one).
if [ ${#missing_py[@]} -gt 0 ]; then
  site_writable=$(python3 -c 'import os, sysconfig
print(int(os.access(sysconfig.get_paths()["purelib"], os.W_OK)))' 2>/dev/null || echo 0)
  pip=(python3 -m pip install --disable-pip-version-check --no-input -q)
  if is_root || [ "$site_writable" = 1 ]; then
    say "installing Python modules for $(command -v python3): ${missing_py[*]}"
    export PIP_ROOT_USER_ACTION=ignore
    if ! "${pip[@]}" "${missing_py[@]}" >"$log" 2>&1; then
      # A Python managed by the distribution (PEP 668) refuses pip unless told otherwise;
      # this is the only case where that is added.
      if grep -q 'externally-managed-environment' "$log"; then
        quietly "${pip[@]}" --break-system-packages "${missing_py[@]}"
      else
        cat "$log" >&2
        say "failed: ${pip[*]} ${missing_py[*]}" >&2
        exit 1
      fi
    fi
  else
    # Debian's own python3 (also the one apt-get is about to install) is externally managed.
    extra=" --break-system-packages"
    if command -v python3 >/dev/null 2>&1 && ! python3 -c 'import os, sys, sysconfig
sys.exit(not os.path.exists(os.path.join(sysconfig.get_paths()["stdlib"], "EXTERNALLY-MANAGED")))' \
      2>/dev/null; then
      extra=""
    fi
    todo+=("python3 -m pip install --user${extra} ${missing_py[*]}")
  fi
fi

# ---------------------------------------------------------------- the dktlbm package
# Editable: the commands run the tree's code, edits included. Skipped when this tree's package
# is what python3 imports already (outside the tree, so that PYTHONPATH does not count).
package_here() {
  [ "$(cd / && env -u PYTHONPATH python3 -c 'import dktlbm, os
print(os.path.dirname(os.path.realpath(dktlbm.__file__)))' 2>/dev/null)" = \
    "$(cd "$root/postproc/dktlbm" && pwd -P)" ]
}
if [ ${#missing_py[@]} -eq 0 ] && command -v python3 >/dev/null 2>&1 && ! package_here; then
  site_writable=$(python3 -c 'import os, sysconfig
print(int(os.access(sysconfig.get_paths()["purelib"], os.W_OK)))' 2>/dev/null || echo 0)
  pip=(python3 -m pip install --disable-pip-version-check --no-input -q)
  # offline when this Python can build an editable wheel itself (setuptools 64 or newer and
  # wheel); else pip fetches them for the build
  if python3 -c 'import setuptools, sys, wheel
sys.exit(int(setuptools.__version__.split(".")[0]) < 64)' >/dev/null 2>&1; then
    pip+=(--no-build-isolation)
  fi
  if is_root || [ "$site_writable" = 1 ]; then
    say "installing the dktlbm package (pip install -e $root) for $(command -v python3)"
    export PIP_ROOT_USER_ACTION=ignore
    if ! "${pip[@]}" -e "$root" >"$log" 2>&1; then
      if grep -q 'externally-managed-environment' "$log"; then
        quietly "${pip[@]}" --break-system-packages -e "$root"
      else
        cat "$log" >&2
        say "failed: ${pip[*]} -e $root" >&2
        exit 1
      fi
    fi
  else
    todo+=("python3 -m pip install --user -e $root")
  fi
fi

if [ ${#todo[@]} -gt 0 ]; then
  say "dktlbm needs software that is not installed yet. Run:" >&2
  printf '  %s\n' "${todo[@]}" >&2
  say "then run tools/setup.sh again." >&2
  exit 1
fi

# ---------------------------------------------------------------- configure and build
if [ ! -f build/build.ninja ]; then
  # A cache left by a configure that failed (e.g. before HDF5 was installed) would keep its
  # NOTFOUND results; start clean.
  rm -f build/CMakeCache.txt
  say "configuring (cmake --preset release)"
  quietly cmake --preset release
fi
quietly cmake --build --preset release
if ! grep -q 'no work to do' "$log"; then
  say "built build/dktlbm"
fi
