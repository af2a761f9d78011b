#!/bin/sh
# The whole pipeline under load: hullguardd on a config with simulated cameras
# publishes over DDS on loopback (in a private network namespace when one can
# be made), `hullguard echo` subscribes, and the latency from each sample's
# capture stamp to its arrival at the subscriber is summarised, with the
# daemon's cycle count, deadline misses and missed cycles (does the rate hold?).
#   tools/perf/pipeline_latency.sh [CONFIG] [SECONDS] [BUILD_DIR]
# Defaults: config/paper_cell.yaml, 20 s, build. Prints one JSON object.
set -eu
root=$(cd "$(dirname "$0")/../.." && pwd)
config=${1:-$root/config/paper_cell.yaml}
seconds=${2:-20}
build=${3:-$root/build}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

run() {
  "$build/daemon/hullguardd" --config "$config" --duration "$seconds" 2> "$out/daemon.log" &
  d=$!
  # Skip the first 3 s (start-up: scene loading, first full octree build).
  sleep 3
  "$build/tools/hullguard" echo --json --topic status --timeout "$((seconds - 4))" \
    > "$out/echo.jsonl" || true
  wait "$d"
}
if [ "${HG_IN_NETNS:-}" != 1 ] && "$root/tests/publish/in_netns.sh" true 2>/dev/null; then
  exec "$root/tests/publish/in_netns.sh" "$0" "$@"
fi
export CYCLONEDDS_URI="file://$root/config/cyclonedds.xml"
run
last=$(grep 'hullguardd: cycle' "$out/daemon.log" | tail -1)
cycles=$(echo "$last" | sed -n 's/.*cycle \([0-9]*\) .*/\1/p')
misses=$(echo "$last" | sed -n 's/.*deadline misses \([0-9]*\) .*/\1/p')
missed=$(echo "$last" | sed -n 's/.*missed cycles \([0-9]*\) .*/\1/p')
latency=$(grep '"summary": "latency"' "$out/echo.jsonl" | tail -1)
samples=$(grep -c '"topic": "status"' "$out/echo.jsonl" || true)
printf '{"config": "%s", "seconds": %s, "cycles": %s, "deadline_misses": %s, "missed_cycles": %s, "status_samples": %s, "latency": %s, "last_health": "%s"}\n' \
  "$(basename "$config")" "$seconds" "${cycles:-0}" "${misses:-0}" "${missed:-0}" "$samples" "${latency:-null}" \
  "$(echo "$last" | sed 's/"/\\"/g')"
