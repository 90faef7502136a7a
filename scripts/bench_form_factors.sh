#!/usr/bin/env bash
# Form-factor benchmarks for BENCHMARKS.md (## Form factors): time and error of every
# method on the Cornell box at ~1k, 4k and 16k elements (per-object matrix against
# ../shared/reference/cornell-box/view_factors_monte_carlo.json), and the full per-element
# matrix of a closed room of ~20k facets with occlusion (View3D's box345.vs3: a 3×4×5 m
# room with two cubes, meshed to 0.073 m).
#
# Usage: scripts/bench_form_factors.sh [cornell|room|all] [runs] > results.jsonl
# Needs ../shared (skips with a message when absent) and a release build.
set -uo pipefail
cd "$(dirname "$0")/.."
B=target/release/radiosity
SHARED=../shared
C=$SHARED/scenes/cornell-box/cornell_box.obj
R=$SHARED/reference/cornell-box/view_factors_monte_carlo.json
ROOM=crates/radiosity/tests/data/box345.vs3
OUT=${TMPDIR:-/tmp}/bench_ff
mkdir -p "$OUT"
what=${1:-all}
runs=${2:-3}
[ -x "$B" ] || { echo "build first: cargo build --release" >&2; exit 1; }

one() { # label, then viewfactors arguments
  local label=$1; shift
  "$B" viewfactors "$@" --quiet --report "$OUT/r.json" 2>/dev/null || { echo "{\"name\":\"$label\",\"failed\":true}"; return; }
  jq -c --arg lbl "$label" '{name: $lbl, method: .method, rows: .rows, surfaces: .surfaces_computed,
      rows_seconds: .form_factors.seconds, total_seconds: .seconds_total, rays: .form_factors.rays,
      max_abs_error: .comparison.max_abs_error, floor_row_error: .comparison.max_abs_error_per_row.floor,
      reciprocity_rel: .diagnostics.reciprocity_max_rel, closure_error: .diagnostics.closure_max_error,
      row_sum_min: .diagnostics.row_sum_min, row_sum_max: .diagnostics.row_sum_max}' "$OUT/r.json"
}

if [ "$what" = cornell ] || [ "$what" = all ]; then
  if [ ! -f "$C" ]; then echo "skipping Cornell: $C not found" >&2; else
    for run in $(seq "$runs"); do
      one "cornell adaptive polygons" "$C" --per object --method adaptive -o "$OUT/F.json" --compare "$R"
      for s in 48 24 12; do
        for m in hemicube point-sampled monte-carlo analytic; do
          one "cornell $m mesh $s" "$C" --per object --method $m --mesh-size $s -o "$OUT/F.json" --compare "$R"
        done
        if [ "$s" != 12 ]; then
          one "cornell adaptive tol1e-3 mesh $s" "$C" --per object --method adaptive --ff-tolerance 1e-3 --mesh-size $s -o "$OUT/F.json" --compare "$R"
        fi
      done
    done
  fi
fi

if [ "$what" = room ] || [ "$what" = all ]; then
  for m in monte-carlo hemicube point-sampled; do
    one "room $m" "$ROOM" --no-enclosure --per element --mesh-size 0.073 --method $m -o "$OUT/room.npy"
    rm -f "$OUT/room.npy"
  done
  # The O(n²) exact methods on a 4× coarser room (≈5.2k elements), to scale from.
  for m in analytic adaptive; do
    extra=""; [ $m = adaptive ] && extra="--ff-tolerance 1e-3"
    one "room $m mesh 0.146" "$ROOM" --no-enclosure --per element --mesh-size 0.146 --method $m $extra -o "$OUT/room.npy"
    rm -f "$OUT/room.npy"
  done
fi
