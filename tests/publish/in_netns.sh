#!/bin/sh
# Runs a command in a private network namespace that has only loopback, with
# Cyclone DDS configured for lo and no multicast (config/cyclonedds.xml), so a
# DDS test can never send anything off this machine nor see other tests.
#   tests/publish/in_netns.sh COMMAND [ARGS...]
# Exits 77 (ctest SKIP_RETURN_CODE) when no network namespace can be made.
set -eu
root=$(cd "$(dirname "$0")/../.." && pwd)

if [ "${HG_IN_NETNS:-}" != 1 ]; then
  export HG_IN_NETNS=1
  # As root a plain network namespace; otherwise try one inside a user namespace.
  if unshare -n true 2>/dev/null; then
    exec unshare -n "$0" "$@"
  elif unshare -rn true 2>/dev/null; then
    exec unshare -rn "$0" "$@"
  fi
  echo "in_netns.sh: cannot create a network namespace; skipping" >&2
  exit 77
fi

ip link set lo up
export CYCLONEDDS_URI="file://$root/config/cyclonedds.xml"
exec "$@"
