#!/usr/bin/env bash
# Runs the standard benchmark set (tests/bench, Google Benchmark) and rewrites the
# generated part of docs/performance.md, the plot docs/images/octree_times.png and
# the raw results docs/benchmarks.json.
#   tools/perf/run_benchmarks.sh [BUILD_DIR]      (default: build)
# Needs python3 and gnuplot. Takes several minutes: the depth-10 runs update
# millions of nodes per frame.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
build=${1:-$root/build}
json=$root/docs/benchmarks.json
"$build/tests/hg_bench" --benchmark_out="$json" --benchmark_out_format=json
python3 "$root/tools/perf/bench_report.py" "$json" "$root/docs/performance.md" \
  "$root/docs/images/octree_times.png"
echo "updated docs/performance.md, docs/images/octree_times.png and docs/benchmarks.json (raw)"
