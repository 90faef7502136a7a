#!/usr/bin/env bash
# End-to-end benchmark: the issue-5 Cornell render (default quality) and the RenderPark
# scenes, each run N times; prints median wall and CPU seconds and the image error against
# the path-traced references. Needs ../shared beside the repository.
# Usage: scripts/bench-render.sh [N]   (after cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/.."
N=${1:-5}
BIN=target/release/radiosity
SHARED=../shared
[ -d "$SHARED/scenes" ] || { echo "skipping: $SHARED/scenes not found"; exit 0; }
OUT=$(mktemp -d)
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
run() { # name, reference exr, light threshold, args...
  local name=$1 ref=$2 thr=$3; shift 3
  : > "$OUT/wall"; : > "$OUT/user"
  for _ in $(seq "$N"); do
    /usr/bin/time -f "%e %U" -o "$OUT/t" "$BIN" render "$@" --exr "$OUT/$name.exr" -o "$OUT/$name.png" --report "$OUT/$name.json" -q 2>/dev/null
    read -r w u < "$OUT/t"; echo "$w" >> "$OUT/wall"; echo "$u" >> "$OUT/user"
  done
  local err
  err=$("$BIN" compare "$OUT/$name.exr" "$ref" --light-threshold "$thr" --json | python3 -c 'import json,sys; print("%.2f" % (100*json.load(sys.stdin)["relative_rmse_light_masked"]))')
  local el
  el=$(python3 -c "import json; print(json.load(open('$OUT/$name.json'))['elements'])")
  printf "%-22s elements %6s  wall %6.2f s  cpu %6.2f s  light-masked rel. RMSE %s %%  (median of %s)\n" \
    "$name" "$el" "$(median < "$OUT/wall")" "$(median < "$OUT/user")" "$err" "$N"
}
echo "machine: $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg)"
run cornell-256 "$SHARED/reference/cornell-box/mitsuba_256x256_16384spp.exr" 1.0 \
  "$SHARED/scenes/cornell-box/cornell_box.obj" --camera "$SHARED/scenes/cornell-box/camera.json" --width 256 --height 256
run office2-256 "$SHARED/reference/renderpark-office2/ref_256_15232spp.exr" 1e9 \
  "$SHARED/scenes/renderpark-office2/office2.obj" --camera "$SHARED/reference/renderpark-office2/camera.json" --width 256 --height 256
run classroom-256 "$SHARED/reference/renderpark-classroom/ref_256_9536spp.exr" 20 \
  "$SHARED/scenes/renderpark-classroom/classroom.obj" --camera "$SHARED/reference/renderpark-classroom/camera.json" --width 256 --height 256
# Ten Gouraud views from one solve against one view (issue 5: < 1.5x), 512x512, the built-in box.
python3 - "$OUT/views.json" <<'PY'
import json, math, sys
views = []
for k in range(10):
    a = math.radians(-20 + 40 * k / 9)
    views.append({"name": "v%d" % k, "position": [278 + 1078 * math.sin(a), 273, 278 - 1078 * math.cos(a)],
                  "look_at": [278, 273, 278], "up": [0, 1, 0], "vfov_deg": 39.3})
json.dump(views, open(sys.argv[1], "w"))
PY
views() { # label, args...
  local label=$1; shift
  : > "$OUT/wall"; : > "$OUT/user"
  for _ in $(seq "$N"); do
    /usr/bin/time -f "%e %U" -o "$OUT/t" "$BIN" render cornell --render gouraud --width 512 --height 512 "$@" -q 2>/dev/null
    read -r w u < "$OUT/t"; echo "$w" >> "$OUT/wall"; echo "$u" >> "$OUT/user"
  done
  printf "%-22s wall %6.2f s  cpu %6.2f s  (median of %s)\n" "$label" "$(median < "$OUT/wall")" "$(median < "$OUT/user")" "$N"
}
views "gouraud 1 view" -o "$OUT/one.png"
views "gouraud 10 views" --views "$OUT/views.json" -o "$OUT/many.png"
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
rm -rf "$OUT"
