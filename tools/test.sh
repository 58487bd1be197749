#!/usr/bin/env bash
# Command B: set up and build (tools/setup.sh), then run every test except the benchmarks and
# the long demonstrations (ctest --preset long).
#
#   tools/test.sh [ctest options...]     e.g. tools/test.sh -L unit
#
# Exit status: ctest's (0 when all tests pass). Benchmarks: ctest --preset perf
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bash "$root/tools/setup.sh"
cd "$root"
# Twice as many tests at once as there are cores: most tests are many short runs whose ranks
# wait on each other, on mpirun's start-up and on the file system, and a test declares as many
# processors as its largest run has ranks. Measured on a 2-core VM (AMD EPYC, 32 MiB L3), the
# whole suite took 1327 s with -j 2 (1.0 core busy on average) and 1092 s with -j 4 (1.4).
exec ctest --preset release -LE 'perf|long' -j "$((2 * $(nproc)))" "$@"
