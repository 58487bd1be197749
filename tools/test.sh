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
exec ctest --preset release -LE 'perf|long' -j "$(nproc)" "$@"
