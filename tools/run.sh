#!/usr/bin/env bash
# Command A: set up and build (tools/setup.sh), then run one scene on MPI ranks; a scene with a
# pair of particles ends with its DKT pattern (printed by dktlbm) and, when the package's
# postproc/dktlbm/gap.py is there, the gap plot (dkt-gap, from this tree) beside the run's HDF5
# file.
#
#   tools/run.sh [scene.nml] [ranks] [dktlbm options...]
#
# Defaults: input/case1.nml (the paper's Case 1) on 2 ranks. Further arguments go to dktlbm,
# e.g. the preview, into a directory of its own so that it never blocks the main run:
#   tools/run.sh input/case1.nml 2 --set lbm.cells_per_diameter=12 \
#     --set output.dir=runs/case1_preview
# The run's files go to output.dir of the scene (default runs/<scene name>, below the
# repository root). A directory that holds an earlier run of the scene is refused by the
# --check below, before anything runs (output.overwrite=.true. or another output.dir).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
scene=${1:-input/case1.nml}
ranks=${2:-2}
shift $(($# < 2 ? $# : 2))

# A scene path is taken relative to where the command was typed; the run happens in the root.
if [ -f "$scene" ]; then
  scene=$(cd "$(dirname "$scene")" && pwd)/$(basename "$scene")
elif [ -f "$root/$scene" ]; then
  scene=$root/$scene
else
  echo "run.sh: scene file $scene not found" >&2
  exit 2
fi
if ! [[ "$ranks" =~ ^[1-9][0-9]*$ ]]; then
  echo "run.sh: ranks must be a positive integer, not '$ranks'" >&2
  exit 2
fi

bash "$root/tools/setup.sh"
cd "$root"

launcher=(mpirun -n "$ranks")
if mpirun --version 2>&1 | grep -Eq 'Open MPI|OpenRTE'; then
  if [ "$(id -u)" -eq 0 ]; then
    export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
  fi
  if [ "$ranks" -gt "$(nproc)" ]; then
    launcher+=(--oversubscribe)
  fi
fi
# Show the scene relative to the root when it lies inside it (as in the README).
case "$scene" in "$root"/*) scene=${scene#"$root"/} ;; esac
# the run's HDF5 file, from the start-up summary of --check ('... into DIR/NAME.h5'); --check
# also refuses what the run would (bad input, too little memory, an earlier run's files)
h5=$("${launcher[@]}" build/dktlbm "$scene" "$@" --check | sed -n 's/.* into \(.*\.h5\)$/\1/p' |
  tail -n 1)
"${launcher[@]}" build/dktlbm "$scene" "$@"
if [ -n "$h5" ] && [ -f postproc/dktlbm/gap.py ] &&
  python3 -c 'import h5py, sys; sys.exit(0 if "diagnostics" in h5py.File(sys.argv[1]) else 1)' \
    "$h5" 2> /dev/null; then
  PYTHONPATH="postproc${PYTHONPATH:+:$PYTHONPATH}" python3 -m dktlbm.gap "$h5"
fi
