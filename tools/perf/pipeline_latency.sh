#!/bin/sh
# The whole pipeline under load: hullguardd on a config with simulated cameras
# publishes over DDS on loopback (in a private network namespace when one can
# be made), `hullguard echo` subscribes, and the latency from each sample's
# capture stamp to its arrival at the subscriber is summarised, with the
# daemon's cycle count, deadline misses and missed cycles (does the rate hold?).
#   tools/perf/pipeline_latency.sh [CONFIG] [SECONDS] [SKIP] [BUILD_DIR]
# Defaults: config/paper_cell.yaml, 20 s, 3 s, build. The first SKIP seconds
# (start-up: scenes, obstacle depth maps, background learning, the first full
# build) are not measured: latency and `window_missed_cycles` cover the rest.
# Prints one JSON object. With HG_LATENCY_OUT=FILE, every measured sample's
# latency (ms) is also written to FILE, one per line (tools/perf/plot_latency.py);
# with HG_ECHO_OUT=FILE, the subscriber's status samples (JSON lines: latency,
# stage times, cameras) are kept in FILE.
set -eu
root=$(cd "$(dirname "$0")/../.." && pwd)
config=${1:-$root/config/paper_cell.yaml}
seconds=${2:-20}
skip=${3:-3}
build=${4:-$root/build}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

run() {
  "$build/daemon/hullguardd" --config "$config" --duration "$seconds" 2> "$out/daemon.log" &
  d=$!
  sleep "$skip"
  "$build/tools/hullguard" echo --json --topic status --timeout "$((seconds - skip - 1))" \
    --latency-out "$out/latency.txt" > "$out/echo.jsonl" || true
  wait "$d"
}
if [ "${HG_IN_NETNS:-}" != 1 ] && "$root/tests/publish/in_netns.sh" true 2>/dev/null; then
  exec "$root/tests/publish/in_netns.sh" "$0" "$@"
fi
export CYCLONEDDS_URI="file://$root/config/cyclonedds.xml"
run
if [ -n "${HG_LATENCY_OUT:-}" ] && [ -f "$out/latency.txt" ]; then cp "$out/latency.txt" "$HG_LATENCY_OUT"; fi
if [ -n "${HG_ECHO_OUT:-}" ]; then cp "$out/echo.jsonl" "$HG_ECHO_OUT"; fi
last=$(grep 'hullguardd: cycle' "$out/daemon.log" | tail -1)
cycles=$(echo "$last" | sed -n 's/.*cycle \([0-9]*\) .*/\1/p')
misses=$(echo "$last" | sed -n 's/.*deadline misses \([0-9]*\) .*/\1/p')
missed=$(echo "$last" | sed -n 's/.*missed cycles \([0-9]*\) .*/\1/p')
latency=$(grep '"summary": "latency"' "$out/echo.jsonl" | tail -1)
samples=$(grep -c '"topic": "status"' "$out/echo.jsonl" || true)
# Missed cycles within the measured window: the last status sample's count
# less the first one's.
window=$(grep '"topic": "status"' "$out/echo.jsonl" | sed -n 's/.*"missed_cycles": \([0-9]*\).*/\1/p' |
  awk 'NR == 1 { first = $1 } { last = $1 } END { if (NR > 0) print last - first; else print "null" }')
printf '{"config": "%s", "seconds": %s, "skipped_s": %s, "cycles": %s, "deadline_misses": %s, "missed_cycles": %s, "window_missed_cycles": %s, "status_samples": %s, "latency": %s, "last_health": "%s"}\n' \
  "$(basename "$config")" "$seconds" "$skip" "${cycles:-0}" "${misses:-0}" "${missed:-0}" "$window" "$samples" "${latency:-null}" \
  "$(echo "$last" | sed 's/"/\\"/g')"
