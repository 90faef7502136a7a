#!/usr/bin/env bash
# Builds and runs the fuzz targets in fuzz/ (cargo-fuzz + libFuzzer) one after another,
# each for SECONDS_PER_TARGET seconds (default 600), and prints one summary line per
# target. Exits non-zero if any run leaves a crash, timeout or out-of-memory artefact in
# fuzz/artifacts/<target>/. See docs/RELIABILITY.md ("Fuzzing").
#
# Usage: scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]
#   FUZZ_SANITIZER=address|none  (default address, cargo-fuzz's default)
#   FUZZ_CMIN=1                   afterwards, merge the new inputs into fuzz/corpus/<target>
#                                 and minimise it (cargo fuzz cmin)
#   FUZZ_NICE=10                  niceness of builds and runs (shared machines)
#
# Needs cargo-fuzz (`cargo install cargo-fuzz`). cargo-fuzz passes nightly-only flags
# (-Zsanitizer, -Cpasses=sancov-module, ...) to rustc; with only a stable toolchain they are
# allowed by RUSTC_BOOTSTRAP=1, which this script sets. (That switch is meant for building
# the compiler itself; it is used here only to build the fuzz binaries, never the library.)
#
# Inputs found during a run go to fuzz/corpus-work/<target>/ (ignored by git); the
# committed seeds in fuzz/corpus/<target>/ are read but not written unless FUZZ_CMIN=1.
set -uo pipefail
cd "$(dirname "$0")/../fuzz"
SECS=${1:-600}
shift || true
TARGETS=("$@")
[ ${#TARGETS[@]} -eq 0 ] && TARGETS=(obj gltf toml vs3 camera)
SAN=${FUZZ_SANITIZER:-address}
NICE=${FUZZ_NICE:-10}
export RUSTC_BOOTSTRAP=1

dict_of() {
  case $1 in
    obj) echo dict/obj.dict ;;
    gltf | camera) echo dict/json.dict ;;
    toml) echo dict/toml.dict ;;
    vs3) echo dict/vs3.dict ;;
  esac
}
count_artefacts() { # crash-*, timeout-*, oom-*, leak-* (not slow-unit-*)
  find "artifacts/$1" -maxdepth 1 -type f \( -name 'crash-*' -o -name 'timeout-*' -o -name 'oom-*' -o -name 'leak-*' \) 2>/dev/null | wc -l
}

# cargo-fuzz's default build: optimised as --release, but with debug assertions and
# overflow checks on, so arithmetic bugs panic instead of wrapping.
BUILD=(cargo fuzz build --sanitizer "$SAN")
echo "building: ${BUILD[*]}"
nice -n "$NICE" "${BUILD[@]}" || { echo "build failed"; exit 2; }

mkdir -p logs
status=0
summary=()
for t in "${TARGETS[@]}"; do
  mkdir -p "corpus-work/$t" "artifacts/$t"
  before=$(count_artefacts "$t")
  log=logs/$t.log
  echo "fuzzing $t for $SECS s (log: fuzz/$log)"
  nice -n "$NICE" cargo fuzz run --sanitizer "$SAN" "$t" "corpus-work/$t" "corpus/$t" -- \
    -max_total_time="$SECS" -rss_limit_mb=2048 -timeout=10 -dict="$(dict_of "$t")" \
    -artifact_prefix="artifacts/$t/" -print_final_stats=1 > "$log" 2>&1
  rc=$?
  after=$(count_artefacts "$t")
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | tail -1 | grep -o '[0-9]*$')
  corp=$(grep -o 'corp: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*$')
  secs=$(grep -o 'Done [0-9]* runs in [0-9]* second' "$log" | tail -1 | awk '{print $5}')
  new=$((after - before))
  line=$(printf "%-7s %6ss  runs %10s  corpus %5s  new crashes %s  (rc %s)" "$t" "${secs:-?}" "${runs:-?}" "${corp:-?}" "$new" "$rc")
  summary+=("$line")
  echo "$line"
  if [ "$new" -gt 0 ] || [ "$rc" -ne 0 ]; then
    status=1
    grep -m1 -A3 -E 'panicked at|ERROR: libFuzzer|==ERROR' "$log" | sed 's/^/    /'
  fi
  if [ "${FUZZ_CMIN:-0}" = 1 ]; then
    cp -n "corpus-work/$t"/* "corpus/$t"/ 2>/dev/null
    nice -n "$NICE" cargo fuzz cmin --sanitizer "$SAN" "$t" "corpus/$t" >> "$log" 2>&1
    python3 make_seeds.py # keep the named hand-made seeds
  fi
done
echo "summary ($SECS s per target, sanitizer $SAN):"
printf '  %s\n' "${summary[@]}"
for t in "${TARGETS[@]}"; do
  n=$(count_artefacts "$t")
  [ "$n" -gt 0 ] && echo "  note: fuzz/artifacts/$t/ holds $n artefact(s) in all (delete them once fixed)"
done
exit $status
