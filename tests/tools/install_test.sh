#!/bin/sh
# An installed hullguard: `cmake --install` into a fresh prefix, then the
# installed daemon checks the installed demo config, and the installed
# `hullguard demo` runs on the installed demo cell (the build tree's on the
# source tree's). Arguments: cmake, the build folder, the source folder.
set -eu
cmake=$1 build=$2 src=$3
prefix=$(mktemp -d)
trap 'rm -rf "$prefix"' EXIT
"$cmake" --install "$build" --prefix "$prefix" >/dev/null
for f in bin/hullguardd bin/hullguard share/hullguard/demo.yaml share/hullguard/cyclonedds.xml \
         share/hullguard/scenes/demo_cell.yaml share/hullguard/demo_cell/obstacles.obj \
         lib/systemd/system/hullguardd.service lib/sysusers.d/hullguard.conf; do
  test -f "$prefix/$f" || { echo "install_test: $f not installed" >&2; exit 1; }
done
"$prefix/bin/hullguardd" --check-config "$prefix/share/hullguard/demo.yaml"
installed=$("$prefix/bin/hullguard" demo --frames 2 --depth 6 --out "$prefix/demo")
echo "$installed" | grep -F "scene file $prefix/share/hullguard/scenes/demo_cell.yaml" || {
  echo "install_test: the installed demo did not take the installed scene:" >&2
  echo "$installed" >&2
  exit 1
}
built=$("$build/tools/hullguard" demo --frames 2 --depth 6 --out "$prefix/demo_build")
echo "$built" | grep -F "scene file $src/config/scenes/demo_cell.yaml" || {
  echo "install_test: the build tree's demo did not take the source tree's scene:" >&2
  echo "$built" >&2
  exit 1
}
