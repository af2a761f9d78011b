#!/usr/bin/env bash
# Runs the standard benchmark set and rewrites the generated part of
# docs/performance.md, the plots docs/images/octree_times.png and
# docs/images/paper_cell_scaling.png, and the raw results docs/benchmarks.json
# (Google Benchmark) and docs/bench_paper_cell.json (`hullguard bench`).
#   tools/perf/run_benchmarks.sh [BUILD_DIR]      (default: build)
# Environment: HG_BENCH_FRAMES (frames per `hullguard bench` run, default 300, so
# that the p99 of the incremental updates is not simply their maximum).
# Needs python3 and gnuplot. Takes 10-20 minutes on two cores: the depth-10 runs
# update millions of nodes per frame.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
build=${1:-$root/build}
frames=${HG_BENCH_FRAMES:-300}
json=$root/docs/benchmarks.json
"$build/tests/hg_bench" --benchmark_out="$json" --benchmark_out_format=json

# The paper cell through `hullguard bench`: depth, camera count and thread count
# varied one at a time around 8 cameras, depth 10, 2 threads.
scene=$root/config/scenes/paper_cell.yaml
runs=$(mktemp -d)
trap 'rm -rf "$runs"' EXIT
run() {  # run NAME ARGS...
  local name=$1
  shift
  echo "hullguard bench $*" >&2
  "$build/tools/hullguard" bench --scene "$scene" --frames "$frames" --start 4 --json "$@" \
    >"$runs/$name.json"
}
for d in 7 8 9; do run "d${d}_c8_t2" --depth "$d" --cameras 8 --threads 2; done
run d10_c8_t2 --depth 10 --cameras 8 --threads 2 --baseline dense:256
for c in 4 6; do run "d10_c${c}_t2" --depth 10 --cameras "$c" --threads 2; done
run d10_c8_t1 --depth 10 --cameras 8 --threads 1
python3 - "$runs" "$root/docs/bench_paper_cell.json" <<'PY'
import glob, json, os, sys
runs = {os.path.basename(p)[:-5]: json.load(open(p)) for p in sorted(glob.glob(sys.argv[1] + "/*.json"))}
json.dump(runs, open(sys.argv[2], "w"), indent=1)
PY
python3 "$root/tools/perf/bench_report.py" "$json" "$root/docs/bench_paper_cell.json" \
  "$root/docs/performance.md" "$root/docs/images"
echo "updated docs/performance.md, docs/images/{octree_times,paper_cell_scaling}.png," \
  "docs/benchmarks.json and docs/bench_paper_cell.json"
