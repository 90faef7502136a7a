#!/usr/bin/env bash
# Bakes scenes with `radiosity bake` and checks each GLB in real consumers:
#  1. the Khronos glTF validator (npm `gltf-validator`): no error, no warning;
#  2. three.js (npm `three`) in headless Chromium (Debian's `chromium`, driven by npm
#     `playwright-core`): the Cornell box drawn from its glTF camera must match our own
#     render of that view at the same exposure, relative RMSE light masked <= 8 % with
#     vertex colours (against the Gouraud and the final-gather render), <= 5 % with the
#     lightmap (against the final gather); the furnace's lightmap must show its one
#     radiance in every pixel (a seam or an unfilled texel would not); with MOZ_lightmap
#     (irradiance under the materials' own colours and textures, read by a loader plugin
#     as Mozilla Hubs does) the Cornell box and a textured room (scripts/textured_room.py:
#     checkerboard floor, striped wall) <= 5 % against the final gather;
#  3. Blender (Debian's `blender`, headless): imports the GLBs with every mesh, its colour
#     attribute, both UV sets (lightmap) and the camera; the textured room's MOZ_lightmap
#     bake with its two base-colour textures.
# npm packages are installed here; chromium by apt when missing and run as root. Each part
# skips with a message when its tools cannot be had.
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
bin="${CARGO_TARGET_DIR:-$root/target}/release/radiosity"
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
"$bin" bake --quiet -o "$out/cornell.glb" || exit 1
"$bin" bake "$root/scenes/cornell-lamps.toml" --quiet -o "$out/cornell-lamps.glb" || exit 1
"$bin" bake furnace --two-sided --quiet -o "$out/furnace-two-sided.glb" || exit 1
k=3
"$bin" bake --quiet --exposure $k -o "$out/cornell-k.glb" || exit 1
"$bin" bake --quiet --exposure $k --lightmap -o "$out/cornell-lightmap.glb" || exit 1
"$bin" bake furnace --quiet --exposure 0.4 --lightmap --lightmap-size 256 -o "$out/furnace-lightmap.glb" || exit 1
"$bin" bake --quiet --exposure $k --lightmap --lightmap-mode moz -o "$out/cornell-moz.glb" || exit 1
python3 "$root/scripts/textured_room.py" "$out/room" || exit 1
kr=0.25
"$bin" bake "$out/room/room.toml" --quiet --exposure $kr --lightmap --lightmap-mode moz -o "$out/room-moz.glb" || exit 1
node "$here/validate.mjs" "$out"/*.glb
status=$?
if [ $status -eq 0 ]; then echo "gltf check: validator passed"; else echo "gltf check: validator FAILED"; fi

# Blender, headless.
blender=$(command -v blender || true)
if [ -z "$blender" ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends blender python3-numpy) >/dev/null 2>&1
  blender=$(command -v blender || true)
fi
if [ -z "$blender" ]; then
  echo "gltf check: Blender SKIPPED (no blender, and apt could not install it)"
else
  for case in "cornell.glb 19 0" "cornell-lightmap.glb 19 2" "room-moz.glb 7 2 2"; do
    set -- $case
    if line=$("$blender" -b --factory-startup --python "$here/blender_import.py" -- "$out/$1" "$2" "$3" ${4:+"$4"} 2>&1 | grep -E "^blender [0-9]"); then
      echo "$1: $line"
      echo "gltf check: Blender import of $1 passed"
    else
      echo "$1: ${line:-blender: the import script printed nothing}"
      echo "gltf check: Blender import of $1 FAILED"
      status=1
    fi
  done
fi

# three.js in headless Chromium.
chromium=${CHROMIUM:-$(command -v chromium || command -v chromium-browser || true)}
if [ -z "$chromium" ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) >/dev/null 2>&1
  chromium=$(command -v chromium || true)
fi
if [ -z "$chromium" ]; then
  echo "gltf check: three.js SKIPPED (no chromium, and apt could not install it)"
  exit $status
fi
"$bin" render --quiet --render gouraud --spp 8 --width 256 --height 256 --exposure $k -o "$out/ours-gouraud.png" || exit 1
"$bin" render --quiet --width 256 --height 256 --exposure $k -o "$out/ours-gather.png" || exit 1
"$bin" render furnace --quiet --width 128 --height 128 --exposure 0.4 -o "$out/ours-furnace.png" || exit 1
"$bin" render "$out/room/room.toml" --quiet --width 256 --height 256 --exposure $kr -o "$out/ours-room.png" || exit 1
shots=${SHOTS:-$out}
# glb, our render, limit, mode, what
for case in "cornell-k gouraud 0.08 colors" "cornell-k gather 0.08 colors" "cornell-lightmap gather 0.05 lightmap" \
            "furnace-lightmap furnace 0.05 uniform:0.8" "cornell-moz gather 0.05 moz" "room-moz room 0.05 moz-textured"; do
  set -- $case
  if CHROMIUM="$chromium" node "$here/three.mjs" "$out/$1.glb" "$out/ours-$2.png" "$shots/three-$1-vs-$2.png" "$3" "$4"; then
    echo "gltf check: three.js $1 against our $2 render passed"
  else
    echo "gltf check: three.js $1 against our $2 render FAILED"
    status=1
  fi
done
exit $status
