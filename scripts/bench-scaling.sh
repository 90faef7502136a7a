#!/usr/bin/env bash
# Scaling series for the hierarchical operator (issue 10): the RenderPark classroom tiled
# k × k (each copy shifted by its floor's size plus a gap, so the rooms are closed and see
# each other only through the rays' visibility), solved with `--transport hierarchical`.
# Prints triangles (of the OBJ faces, fanned), elements, links, wall seconds, peak
# resident memory and the escaped share of the energy line (negative: light created) per
# k, and the growth exponents of time and memory against elements and against triangles
# (least squares on log–log). Without EXTRA each k runs at its defaults (the mesh size
# grows with the scene): the series from 10^4 to 10^6 triangles is
#   scripts/bench-scaling.sh 1 2 4 7 11 The classroom's own mesh size (0.3853) and, as the link
# minimum size, the same (the default above 50 000 elements until 2026-12-05; now twice
# the mesh size) keep every k in one regime:
#   EXTRA="--mesh-size 0.3853 --link-min-size 0.3853" scripts/bench-scaling.sh 1 2 4 7 10
# Needs ../shared beside the repository.
# Usage: scripts/bench-scaling.sh [K...]   (after cargo build --release; default: 1 2 3 4;
#        BIN=path/to/radiosity to time another build)
#        EXTRA="--mesh-size 0.5" scripts/bench-scaling.sh 1 2 4
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/radiosity}
SRC=$(cd .. && pwd)/shared/scenes/renderpark-classroom/classroom.obj
[ -f "$SRC" ] || { echo "skipping: ../shared/scenes/renderpark-classroom/classroom.obj not found"; exit 0; }
KS=("$@")
[ ${#KS[@]} -gt 0 ] || KS=(1 2 3 4)
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
echo "machine: $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg)"
printf "%4s %10s %10s %12s %9s %9s %9s\n" k triangles elements links wall_s peak_MB escaped
: > "$OUT/series"
for k in "${KS[@]}"; do
  python3 - "$SRC" "$k" "$OUT/tiles-$k.obj" <<'PY'
import sys
src, k, dst = sys.argv[1], int(sys.argv[2]), sys.argv[3]
lines = open(src).read().splitlines()
vs = [list(map(float, l.split()[1:4])) for l in lines if l.startswith('v ')]
lo = [min(v[i] for v in vs) for i in range(3)]; hi = [max(v[i] for v in vs) for i in range(3)]
dx, dy = (hi[0] - lo[0]) * 1.05, (hi[1] - lo[1]) * 1.05
nv = len(vs)
with open(dst, 'w') as f:
    mtl = [l for l in lines if l.startswith('mtllib')]
    for l in mtl:
        f.write(l.replace('mtllib ', 'mtllib ' + src.rsplit('/', 1)[0] + '/') + '\n')
    for a in range(k):
        for b in range(k):
            t = (a * k + b) * nv
            for l in lines:
                if l.startswith('v '):
                    x, y, z = map(float, l.split()[1:4])
                    f.write('v %.6f %.6f %.6f\n' % (x + a * dx, y + b * dy, z))
                elif l.startswith('f '):
                    idx = [str(int(p.split('/')[0]) + t) for p in l.split()[1:]]
                    f.write('f ' + ' '.join(idx) + '\n')
                elif l.startswith(('g ', 'usemtl', 'o ')):
                    f.write(l + '\n')
PY
  tris=$(awk '/^f /{t += NF - 3} END{print t}' "$OUT/tiles-$k.obj")
  # shellcheck disable=SC2086
  /usr/bin/time -f "%e %M" -o "$OUT/t" "$BIN" solve "$OUT/tiles-$k.obj" --transport hierarchical ${EXTRA:-} \
    -q --report "$OUT/r.json" > /dev/null 2> "$OUT/err" || { echo "k=$k failed:"; tail -3 "$OUT/err"; continue; }
  read -r wall kb < "$OUT/t"
  read -r el links esc < <(python3 -c "import json; r=json.load(open('$OUT/r.json')); e=r['energy']; print(r['elements'], r['form_factors']['hierarchy']['links'], '%+.2f%%' % (100 * e['escaped'][1] / e['emitted'][1]))")
  printf "%4s %10s %10s %12s %9.2f %9.0f %9s\n" "$k" "$tris" "$el" "$links" "$wall" "$((kb / 1024))" "$esc"
  echo "$el $wall $kb $tris" >> "$OUT/series"
done
python3 - "$OUT/series" <<'PY'
import math, sys
rows = [tuple(map(float, l.split())) for l in open(sys.argv[1]) if l.strip()]
if len(rows) >= 2:
    def slope(i, against=0):
        xs = [math.log(r[against]) for r in rows]; ys = [math.log(r[i]) for r in rows]
        mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
        return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs)
    print("growth exponent against elements: time %.2f, peak memory %.2f" % (slope(1), slope(2)))
    print("growth exponent against triangles: time %.2f, peak memory %.2f" % (slope(1, 3), slope(2, 3)))
PY
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
