#!/usr/bin/env bash
# Bakes scenes with `radiosity bake` and checks each GLB with the Khronos glTF validator
# (npm `gltf-validator`, installed here). Fails on any validator error or warning; skips
# with a message when npm or the registry is not available.
#   checks/gltf/run.sh
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
if ! command -v npm >/dev/null || ! command -v node >/dev/null; then
  echo "gltf check: SKIPPED (node/npm not found)"
  exit 0
fi
if ! (cd "$here" && npm install --no-audit --no-fund --loglevel=error >/dev/null); then
  echo "gltf check: SKIPPED (npm install gltf-validator failed: no registry?)"
  exit 0
fi
cargo build --release -q -p radiosity-cli --manifest-path "$root/Cargo.toml" || exit 1
bin="$root/target/release/radiosity"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
"$bin" bake --quiet -o "$out/cornell.glb" || exit 1
"$bin" bake "$root/scenes/cornell-lamps.toml" --quiet -o "$out/cornell-lamps.glb" || exit 1
"$bin" bake furnace --two-sided --quiet -o "$out/furnace-two-sided.glb" || exit 1
node "$here/validate.mjs" "$out"/*.glb
status=$?
if [ $status -eq 0 ]; then echo "gltf check: passed"; else echo "gltf check: FAILED"; fi
exit $status
