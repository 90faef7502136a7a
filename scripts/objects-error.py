#!/usr/bin/env python3
"""Per-object error of a radiosity report against a reference objects.json.

Usage: scripts/objects-error.py REPORT.json ../shared/reference/renderpark-classroom/objects.json

Compares the luminance of each object's mean radiance (`objects[i].radiance_rgb` in the
report written by `radiosity solve|render --report`) with the reference's `L_rgb`,
skipping emitters and objects the reference sees as black. Prints the median |error|,
the area-weighted bias and the worst object: the per-object numbers of BENCHMARKS.md.
"""
import json
import statistics
import sys


def lum(c):
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    rep = json.load(open(sys.argv[1]))
    ref = {o["name"]: o for o in json.load(open(sys.argv[2]))["objects"]}
    errs, wa, ws = [], 0.0, 0.0
    for o in rep["objects"]:
        r = ref.get(o["name"])
        if not r or r.get("emissive"):
            continue
        b = lum(r["L_rgb"])
        if b <= 0:
            continue
        a = lum(o["radiance_rgb"])
        errs.append(((a - b) / b, o["name"]))
        wa += r["area"] * (a - b)
        ws += r["area"] * b
    if not errs:
        sys.exit("no object of the report is in the reference")
    errs.sort(key=lambda e: -abs(e[0]))
    med = statistics.median(abs(e) for e, _ in errs)
    print(f"{len(errs)} objects, median |err| {100 * med:.2f} %, area bias {100 * wa / ws:+.2f} %, "
          f"worst {errs[0][1]} {100 * errs[0][0]:+.1f} %")


if __name__ == "__main__":
    main()
