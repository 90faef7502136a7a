#!/usr/bin/env python3
"""Side-by-side comparison of `radiosity` (this package) with pyviewfactor.

What it measures
----------------
For three cases, the wall time (time.perf_counter) of one measured call and the
error against a reference, for both tools:

1. Unit cube, 6 inward-facing faces, all 30 off-diagonal pairs.  Reference: the
   closed forms for opposite (0.199824895698) and adjacent (0.200043776075) unit
   squares (Howell C-11 / C-14); nothing is occluded inside a cube.
2. Cornell box, 19 quads, occlusion by the two blocks.  Reference: the Monte
   Carlo matrix in crates/radiosity/tests/data/cornell_view_factors_monte_carlo.json
   (std error <= 2.5e-4, so errors below ~5e-4 are at the reference's noise).
3. Two parallel 1x1 plates at distance 1, each split into an N x N grid of
   squares (default N = 40, i.e. 3200 facets).  The full facet-to-facet matrix is
   computed, then aggregated to the plate-to-plate factor
   sum_{i in A, j in B} a_i F_ij / A_A, whose exact value is 0.199824895698.

Conventions (checked at run time)
---------------------------------
* Both tools take the front side of a polygon by the right-hand rule (Newell
  normal); the same vertex/face arrays are fed to both.
* `radiosity.view_factors` returns F[i, j] = F(i -> j); pyviewfactor's
  `compute_viewfactor_matrix` returns F[i, j] = F(j -> i), so it is transposed.
* pyviewfactor decides visibility and obstruction per *pair of facets*, in a
  binary way: visible iff the centroid-to-centroid vector is in front of both
  facets, obstructed iff the centroid-to-centroid segment hits an obstacle
  triangle (`obstacles=`, BVH) or, with `strict_obstruction=True`, iff any
  vertex-to-vertex segment does.  A visible, unobstructed pair gets the full
  unoccluded (SA-30 contour integral) value, otherwise 0.  Partial visibility or
  partial occlusion therefore needs the faces to be subdivided; for the Cornell
  box it is run on the 19 faces as given and on each face split into k x k
  sub-quads (bilinear), with the obstacle mesh = the (subdivided) scene itself,
  and the result aggregated back to 19 x 19 by area.
* The notes also give the form-factor time reported in our diagnostics.
* The pyviewfactor functions are Numba-jitted; one warm-up call on a small mesh
  compiles them before anything is timed (its time is printed separately).  Ours
  gets one warm-up call per method on the cube.

How to run
----------
    pip install ./crates/radiosity-py pyviewfactor
    python crates/radiosity-py/bench/compare_pyviewfactor.py

Options: --plate-n N (grid per plate, default 40), --cornell-subdiv LIST (default
"1,4,8,16"; 16 takes ~2 min on 2 cores), --pvf-plate-rows K (time only K random
facets of plate A with pyviewfactor and extrapolate the time linearly; default 0 =
all rows), --skip-ours-adaptive-plates.  Total run time with the defaults: about 5-6 minutes on 2 cores.
If pyviewfactor cannot be imported, only our rows are run and the pyviewfactor rows
say how to install it.
"""

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

import radiosity

F_OPPOSITE = 0.199824895698  # unit squares, parallel, distance 1 (Howell C-11)
F_ADJACENT = 0.200043776075  # unit squares, common edge, 90 degrees (Howell C-14)

REPO = Path(__file__).resolve().parents[3]
CORNELL_REF = REPO / "crates" / "radiosity" / "tests" / "data" / "cornell_view_factors_monte_carlo.json"

PVF_INSTALL = "pip install pyviewfactor   (pulls in pyvista, vtk and numba)"

ROWS = []


def row(case, tool, method, seconds, error, notes=""):
    ROWS.append((case, tool, method, seconds, error, notes))


def fmt_time(t):
    if t is None:
        return "-"
    return f"{t:.3g}" if t < 100 else f"{t:.0f}"


def fmt_err(e):
    if e is None:
        return "-"
    if isinstance(e, str):
        return e
    return f"{e:.2e}"


def ours(vertices, faces, **kw):
    """radiosity.view_factors timed; also returns the kernel time from the diagnostics."""
    (F, areas, diag), t = timed(radiosity.view_factors, vertices, faces, **kw)
    inner = (diag.get("form_factors") or {}).get("seconds")
    return F, areas, t, (f"form factors {inner:.2g} s" if inner is not None else "")


def timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t0


# ----------------------------------------------------------------------------
# geometry
# ----------------------------------------------------------------------------

def newell_normal(p):
    p = np.asarray(p, float)
    q = np.roll(p, -1, axis=0)
    n = np.array([
        np.sum((p[:, 1] - q[:, 1]) * (p[:, 2] + q[:, 2])),
        np.sum((p[:, 2] - q[:, 2]) * (p[:, 0] + q[:, 0])),
        np.sum((p[:, 0] - q[:, 0]) * (p[:, 1] + q[:, 1])),
    ])
    return n  # length = 2 * area


def polygon_areas(vertices, faces):
    return np.array([0.5 * np.linalg.norm(newell_normal(vertices[f])) for f in faces])


def unit_cube_inward():
    """8 corners, 6 quads whose right-hand-rule normal points into the cube."""
    v = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    idx = {tuple(p): i for i, p in enumerate(v.astype(int).tolist())}
    faces, kinds = [], []
    for axis in range(3):
        for side in (0, 1):
            a, b = [k for k in range(3) if k != axis]
            quad = []
            for (s, t) in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = [0, 0, 0]
                p[axis], p[a], p[b] = side, s, t
                quad.append(idx[tuple(p)])
            c = v[quad].mean(axis=0)
            if np.dot(newell_normal(v[quad]), np.array([0.5, 0.5, 0.5]) - c) < 0:
                quad = quad[::-1]
            faces.append(quad)
            kinds.append(axis)
    faces = np.array(faces)
    for f in faces:  # sanity: inward
        assert np.dot(newell_normal(v[f]), 0.5 - v[f].mean(axis=0)) > 0
    ref = np.empty((6, 6))
    for i in range(6):
        for j in range(6):
            ref[i, j] = 0.0 if i == j else (F_OPPOSITE if kinds[i] == kinds[j] else F_ADJACENT)
    return v, faces, ref


def parallel_plates(n):
    """Plate A at z=0 facing +z, plate B at z=1 facing -z, each n x n squares."""
    xs = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    grid = np.column_stack([X.ravel(), Y.ravel()])
    va = np.column_stack([grid, np.zeros(len(grid))])
    vb = np.column_stack([grid, np.ones(len(grid))])
    v = np.vstack([va, vb])
    off = len(grid)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    i, j = i.ravel(), j.ravel()
    g = lambda a, b: a * (n + 1) + b  # noqa: E731
    fa = np.column_stack([g(i, j), g(i + 1, j), g(i + 1, j + 1), g(i, j + 1)])  # ccw from +z
    fb = fa[:, ::-1] + off  # ccw from -z
    faces = np.vstack([fa, fb])
    assert newell_normal(v[faces[0]])[2] > 0 and newell_normal(v[faces[-1]])[2] < 0
    return v, faces


def subdivide_quads(vertices, faces, k):
    """Split every quad into k x k bilinear sub-quads (same winding); owner per sub-quad."""
    if k == 1:
        return np.asarray(vertices, float), [list(f) for f in faces], np.arange(len(faces))
    vv, ff, owner = [], [], []
    uu = np.linspace(0.0, 1.0, k + 1)
    for o, q in enumerate(faces):
        p0, p1, p2, p3 = (np.asarray(vertices[i], float) for i in q)
        base = len(vv)
        for u in uu:
            for w in uu:
                vv.append((1 - u) * (1 - w) * p0 + u * (1 - w) * p1 + u * w * p2 + (1 - u) * w * p3)
        g = lambda a, b: base + a * (k + 1) + b  # noqa: E731
        for a in range(k):
            for b in range(k):
                ff.append([g(a, b), g(a + 1, b), g(a + 1, b + 1), g(a, b + 1)])
                owner.append(o)
    return np.array(vv), ff, np.array(owner)


def aggregate(F, areas, owner, n_groups):
    """Facet matrix F(i->j) -> group matrix by area weighting of the rows."""
    S = np.zeros((len(owner), n_groups))
    S[np.arange(len(owner)), owner] = 1.0
    A = S.T @ areas
    return (S.T @ (areas[:, None] * F) @ S) / A[:, None]


def plate_aggregate(F, areas, n_a):
    """sum_{i in A, j in B} a_i F_ij / A_A, plate A = first n_a rows."""
    return float(areas[:n_a] @ F[:n_a, n_a:].sum(axis=1) / areas[:n_a].sum())


# ----------------------------------------------------------------------------
# pyviewfactor helpers
# ----------------------------------------------------------------------------

def pvf_mesh(pv, vertices, faces):
    cells = np.concatenate([[len(f), *f] for f in faces]).astype(np.int64)
    return pv.PolyData(np.asarray(vertices, float), cells)


def pvf_matrix(pvf, mesh, **kw):
    """pyviewfactor matrix transposed to F[i, j] = F(i -> j)."""
    return pvf.compute_viewfactor_matrix(mesh, **kw).T


# ----------------------------------------------------------------------------
# cases
# ----------------------------------------------------------------------------

def case_cube(pvf, pv):
    case = "1 cube (6 faces, 30 pairs)"
    v, f, ref = unit_cube_inward()
    off = ~np.eye(6, dtype=bool)
    for method in ("adaptive", "analytic"):
        F, _, t, inner = ours(v, f, method=method)
        err = np.abs(F - ref)[off].max()
        row(case, "radiosity", method, t, err,
            ("exact, no occlusion" if method == "analytic" else "default method, exact occlusion")
            + f"; {inner}")
    if pvf is None:
        row(case, "pyviewfactor", "-", None, "skipped", "not installed: " + PVF_INSTALL)
        return
    mesh = pvf_mesh(pv, v, f)
    F, t = timed(pvf_matrix, pvf, mesh)
    err = np.abs(F - ref)[off].max()
    row(case, "pyviewfactor", "compute_viewfactor_matrix (SA-30)", t, err,
        f"no obstacles; {np.count_nonzero(F[off])}/30 pairs non-zero")


def case_cornell(pvf, pv, subdivs):
    case = "2 Cornell box (19 faces, occlusion)"
    ref_json = json.loads(CORNELL_REF.read_text())
    R = np.array(ref_json["F_i_to_j"], float)
    names = ref_json["faces"]
    scene = radiosity.load_scene("cornell")
    v, f, surfaces, obstruction = scene.arrays()
    assert list(scene.objects) == names, "scene object order differs from the reference"
    assert not np.any(obstruction)
    areas = polygon_areas(v, f)
    area_dev = np.abs(areas / np.array(ref_json["areas_mm2"]) - 1).max()

    def where(E):
        i, j = np.unravel_index(np.argmax(E), E.shape)
        return f"worst {names[i]}->{names[j]}"

    for method, note in (("adaptive", "default, exact occlusion (clipped shadows)"),
                         ("monte-carlo", "seed 0, default sample counts"),
                         ("analytic", "IGNORES occlusion (for scale only)")):
        F, _, t, inner = ours(v, f, method=method)
        E = np.abs(F - R)
        row(case, "radiosity", method, t, E.max(),
            f"{note}; mean {E.mean():.1e}; {where(E)}; {inner}")
    if pvf is None:
        row(case, "pyviewfactor", "-", None, "skipped", "not installed: " + PVF_INSTALL)
        return
    variants = [(k, False) for k in subdivs]
    if 1 in subdivs:
        variants.insert(subdivs.index(1) + 1, (1, True))
    for k, strict in variants:
        vk, fk, owner = subdivide_quads(v, f, k)
        mesh = pvf_mesh(pv, vk, fk)
        Fk, t = timed(pvf_matrix, pvf, mesh, obstacles=mesh, strict_obstruction=strict)
        ak = polygon_areas(vk, fk)
        G = aggregate(Fk, ak, owner, len(names))
        E = np.abs(G - R)
        what = "as given (19 facets)" if k == 1 else f"{k}x{k} per face ({len(fk)} facets), aggregated"
        method = ("SA-30, obstacles=scene, " +
                  ("strict_obstruction (all vertex rays)" if strict else "centroid ray"))
        row(case, "pyviewfactor", method, t, E.max(),
            f"{what}; mean {E.mean():.1e}; {where(E)}")
    row(case, "(reference)", "Monte Carlo, Mitsuba", None, "-",
        f"std err <= {ref_json['std_err_max']}; polygon areas vs reference areas: {area_dev:.0e} rel.")


def case_plates(pvf, pv, n, pvf_rows, skip_adaptive, rng):
    nf = n * n
    case = f"3 plates {n}x{n}+{n}x{n} ({2 * nf} facets)"
    v, f = parallel_plates(n)
    areas = polygon_areas(v, f)
    for method in ("analytic", "adaptive"):
        if method == "adaptive" and skip_adaptive:
            row(case, "radiosity", method, None, "skipped", "--skip-ours-adaptive-plates")
            continue
        F, a, t, inner = ours(v, f, method=method, surfaces=None)
        err = abs(plate_aggregate(F, a, nf) - F_OPPOSITE)
        row(case, "radiosity", method, t, err,
            f"full {2 * nf}x{2 * nf} facet matrix (incl. coplanar zero pairs), aggregated; {inner}")
    if pvf is None:
        row(case, "pyviewfactor", "-", None, "skipped", "not installed: " + PVF_INSTALL)
        return
    method = "compute_viewfactor_matrix (SA-30)"
    if pvf_rows and pvf_rows < nf:
        rows_a = np.sort(rng.choice(nf, size=pvf_rows, replace=False))
        fs = np.vstack([f[rows_a], f[nf:]])
        mesh = pvf_mesh(pv, v, fs)
        F, t = timed(pvf_matrix, pvf, mesh)
        a = polygon_areas(v, fs)
        est = float(a[:pvf_rows] @ F[:pvf_rows, pvf_rows:].sum(axis=1) / a[:pvf_rows].sum())
        t_full = t * nf / pvf_rows
        row(case, "pyviewfactor", method, t_full, abs(est - F_OPPOSITE),
            f"EXTRAPOLATED: timed {pvf_rows} random rows of plate A x {nf} of B ({t:.3g} s) "
            f"x {nf}/{pvf_rows}; error from those rows only")
        return
    mesh = pvf_mesh(pv, v, f)
    F, t = timed(pvf_matrix, pvf, mesh)
    err = abs(plate_aggregate(F, areas, nf) - F_OPPOSITE)
    _, t_pre = timed(pvf.ProcessedGeometry, mesh)
    row(case, "pyviewfactor", method, t, err,
        f"all {nf}x{nf} plate-to-plate pairs (coplanar pairs culled by its visibility test); "
        f"~{t_pre:.2g} s of it is per-cell geometry preprocessing")


# ----------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plate-n", type=int, default=40)
    ap.add_argument("--cornell-subdiv", default="1,4,8,16")
    ap.add_argument("--pvf-plate-rows", type=int, default=0)
    ap.add_argument("--skip-ours-adaptive-plates", action="store_true")
    args = ap.parse_args()
    subdivs = [int(s) for s in args.cornell_subdiv.split(",") if s.strip()]

    try:
        import pyviewfactor as pvf
        import pyvista as pv
    except Exception as e:  # ImportError, or a broken vtk
        pvf = pv = None
        print(f"NOTE: pyviewfactor could not be imported ({type(e).__name__}: {e}).")
        print(f"      Only radiosity is run. To compare, install it: {PVF_INSTALL}\n")

    versions = [f"python {platform.python_version()}", f"radiosity {radiosity.__version__}",
                f"numpy {np.__version__}"]
    if pvf is not None:
        import numba
        import vtk
        versions += [f"pyviewfactor {pvf.__version__}", f"pyvista {pv.__version__}",
                     f"vtk {vtk.vtkVersion.GetVTKVersion()}", f"numba {numba.__version__} "
                     f"({numba.get_num_threads()} threads)"]
    try:
        ncpu = len(os.sched_getaffinity(0))
    except AttributeError:
        ncpu = os.cpu_count()
    print("versions: " + ", ".join(versions))
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs ({ncpu} usable), {platform.platform()}")

    # warm-ups (not timed in the table)
    cv, cf, _ = unit_cube_inward()
    t0 = time.perf_counter()
    for m in ("adaptive", "analytic", "monte-carlo"):
        radiosity.view_factors(cv, cf, method=m)
    t_ours = time.perf_counter() - t0
    msg = f"warm-up: radiosity {t_ours:.2f} s"
    if pvf is not None:
        t0 = time.perf_counter()
        cube = pvf_mesh(pv, cv, cf)
        pvf.compute_viewfactor_matrix(cube, obstacles=cube)
        pvf.compute_viewfactor_matrix(cube, obstacles=cube, strict_obstruction=True)
        msg += f", pyviewfactor (Numba JIT compile) {time.perf_counter() - t0:.2f} s"
    print(msg + "\n", flush=True)

    rng = np.random.default_rng(0)
    case_cube(pvf, pv)
    case_cornell(pvf, pv, subdivs)
    case_plates(pvf, pv, args.plate_n, args.pvf_plate_rows, args.skip_ours_adaptive_plates, rng)

    print("| case | tool | method | time [s] | max abs error (case 3: aggregated error) | notes |")
    print("|---|---|---|---|---|---|")
    for case, tool, method, t, e, notes in ROWS:
        print(f"| {case} | {tool} | {method} | {fmt_time(t)} | {fmt_err(e)} | {notes} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
