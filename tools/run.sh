#!/usr/bin/env bash
# Command A: set up and build (tools/setup.sh), then run one scene on MPI ranks.
#
#   tools/run.sh [scene.nml] [ranks] [dktlbm options...]
#
# Defaults: input/channel.nml on 2 ranks. Further arguments go to dktlbm, e.g.
#   tools/run.sh input/case1.nml 2 --set run.t_end=0.5
# The run's files go to output.dir of the scene (default runs/<scene name>, below the
# repository root).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
scene=${1:-input/channel.nml}
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
exec "${launcher[@]}" build/dktlbm "$scene" "$@"
