"""The Python package against closed forms and committed references.

Run: pip install ./crates/radiosity-py pytest && pytest crates/radiosity-py/tests
"""

import json
import math
import pathlib
import signal
import threading
import time

import numpy as np
import pytest

import radiosity

DATA = pathlib.Path(__file__).resolve().parents[2] / "radiosity" / "tests" / "data"
SIGMA = radiosity.STEFAN_BOLTZMANN
OPPOSITE = 0.199824895698  # unit squares facing at distance 1 (Howell C-11)
ADJACENT = 0.200043776075  # unit squares sharing an edge at 90 degrees (Howell C-14)


def unit_cube():
    """The unit cube's 6 faces, wound inward: floor, ceiling, y=0, y=1, x=0, x=1."""
    v = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    outward = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])
    return v, outward[:, ::-1].copy()


def grid_plate(n, z, up):
    """A unit square at height z split into n x n squares facing up (or down)."""
    xs = np.linspace(0, 1, n + 1)
    v = np.array([[x, y, z] for y in xs for x in xs])
    faces = []
    for j in range(n):
        for i in range(n):
            a, b, c, d = j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i
            faces.append([a, b, c, d] if up else [a, d, c, b])
    return v, np.array(faces)


@pytest.mark.parametrize("method", ["analytic", "adaptive"])
def test_unit_cube_closed_forms(method):
    v, f = unit_cube()
    F, areas, diag = radiosity.view_factors(v, f, method=method)
    assert F.shape == (6, 6) and F.dtype == np.float64
    np.testing.assert_allclose(areas, 1.0, rtol=1e-12)
    for i in range(6):
        for j in range(6):
            exact = 0.0 if i == j else OPPOSITE if i // 2 == j // 2 else ADJACENT
            assert abs(F[i, j] - exact) < 1e-6, (i, j, F[i, j], exact)
    np.testing.assert_allclose(F.sum(axis=1), 1.0, atol=1e-6)
    assert diag["view_factors"]["reciprocity_max_rel"] < 1e-9


def test_cornell_faces_with_occlusion_match_the_reference():
    ref = json.loads((DATA / "cornell_view_factors_monte_carlo.json").read_text())
    scene = radiosity.load_scene("cornell")
    v, faces, surfaces, blocks = scene.arrays()
    assert scene.objects == ref["faces"]
    F, areas, _ = radiosity.view_factors(v, faces, surfaces=surfaces, method="adaptive")
    R = np.array(ref["F_i_to_j"] if "F_i_to_j" in ref else ref["matrix"])
    err = np.abs(F - R).max()
    assert err <= 1e-3, f"max |F - reference| = {err}"  # the reference's 4 sigma is 1e-3


def test_grids_sum_to_the_plate_factor_and_obstructions_block():
    va, fa = grid_plate(6, 0.0, True)
    vb, fb = grid_plate(6, 1.0, False)
    v = np.vstack([va, vb])
    f = np.vstack([fa, fb + len(va)])
    labels = np.r_[np.zeros(len(fa), int), np.ones(len(fb), int)]
    F, areas, _ = radiosity.view_factors(v, f, surfaces=labels, method="analytic")
    assert F.shape == (2, 2)
    assert abs(F[0, 1] - OPPOSITE) < 1e-9
    # The full facet matrix aggregates to the same factor.
    Ff, af, _ = radiosity.view_factors(v, f, method="analytic")
    n = len(fa)
    agg = (af[:n, None] * Ff[:n, n:]).sum() / af[:n].sum()
    assert abs(agg - OPPOSITE) < 1e-9
    # A plate between them, listed as an obstruction, blocks everything and has no row.
    vc, fc = grid_plate(1, 0.5, True)
    v2 = np.vstack([v, vc])
    f2 = [list(x) for x in f] + [list(fc[0] + len(v))]
    blocks = np.zeros(len(f2), bool)
    blocks[-1] = True
    F2, _, _ = radiosity.view_factors(v2, f2, surfaces=np.r_[labels, 9], obstructions=blocks, method="point-sampled")
    assert F2.shape == (2, 2) and F2[0, 1] < 1e-12


def network_q(t1, t2, e1, e2, f12, f1r, f2r):
    """Heat from surface 1 to 2 (unit areas) with a re-radiating third surface."""
    parallel = f12 + 1.0 / (1.0 / f1r + 1.0 / f2r)
    return SIGMA * (t1**4 - t2**4) / ((1 - e1) / e1 + 1.0 / parallel + (1 - e2) / e2)


def test_exchange_three_surface_network_and_balance():
    v, f = unit_cube()
    labels = np.array([0, 1, 2, 2, 2, 2])  # floor, ceiling, walls as one re-radiating surface
    nan = math.nan
    r = radiosity.exchange(v, f, [0.8, 0.5, 0.3], temperature=[600.0, 300.0, nan], adiabatic=[False, False, True],
                           surfaces=labels, method="analytic", mesh_size=0, enclosure=True)
    q = network_q(600.0, 300.0, 0.8, 0.5, OPPOSITE, 1 - OPPOSITE, 1 - OPPOSITE)
    assert abs(r["heat"][0] - q) < 1e-6 * q, (r["heat"][0], q)
    assert abs(r["balance"]) <= 1e-9 * r["total"]
    assert abs(r["heat"][2]) <= 1e-9 * r["total"]
    # The re-radiating walls sit at the temperature that carries no net heat, between the two.
    assert 300.0 < r["temperature"][2] < 600.0


def blackbody_fraction(lt):
    """Share of blackbody emission below lambda*T (um K), by quadrature of Planck's law."""
    c2 = 14387.768775
    x = np.linspace(c2 / lt, c2 / lt + 60.0, 200001)
    y = x**3 / np.expm1(x)
    return 15 / math.pi**4 * float(np.sum((y[1:] + y[:-1]) * np.diff(x)) / 2)


def test_exchange_in_bands_is_each_band_grey():
    """Floor and ceiling of the unit cube in two bands (split at 4 um), black walls at 0 K:
    in each band a grey two-surface exchange of that band's share of the emission, plus
    what the walls absorb, solved here by hand from the exact factors."""
    v, f = unit_cube()
    labels = np.array([0, 1, 2, 2, 2, 2])
    eps = np.array([[0.9, 0.1], [0.2, 0.9], [1.0, 1.0]])
    t = np.array([900.0, 300.0, 0.0])
    r = radiosity.exchange(v, f, eps, temperature=t, surfaces=labels, method="analytic", mesh_size=0,
                           band_edges=[4.0])
    f12 = OPPOSITE
    for b in range(2):
        share = [blackbody_fraction(4.0 * ti) if ti > 0 else 0.0 for ti in t[:2]]
        if b == 1:
            share = [1.0 - s for s in share]
        e = [SIGMA * share[i] * t[i] ** 4 for i in range(2)]
        e1, e2 = eps[0, b], eps[1, b]
        # J1 = e1 E1 + (1 - e1) F12 J2, J2 = e2 E2 + (1 - e2) F12 J1 (the walls send nothing).
        a = np.array([[1.0, -(1 - e1) * f12], [-(1 - e2) * f12, 1.0]])
        j = np.linalg.solve(a, [e1 * e[0], e2 * e[1]])
        q1 = j[0] - f12 * j[1]
        assert abs(r["band_heat"][0, b] - q1) <= 1e-6 * abs(q1), (b, r["band_heat"][0, b], q1)
    np.testing.assert_allclose(r["band_heat"].sum(axis=1), r["heat"], rtol=1e-9, atol=1e-9 * r["total"])
    assert r["band_edges"] == [4.0]
    assert abs(r["balance"]) <= 1e-9 * r["total"]


def test_exchange_factors_close_and_are_reciprocal():
    v, f = unit_cube()
    x = radiosity.exchange_factors(v, f, [0.9, 0.5, 0.7, 0.7, 0.3, 0.3], mesh_size=0.25, enclosure=True)
    np.testing.assert_allclose(x["gebhart"].sum(axis=1), 1.0, atol=1e-9)
    gr = x["conductance"]
    np.testing.assert_allclose(gr, gr.T, rtol=1e-9, atol=1e-12)
    assert x["reciprocity"] < 1e-9


def test_furnace_solve_is_e_over_one_minus_rho():
    out = radiosity.solve(radiosity.load_scene("furnace"), tolerance=1e-10, max_iterations=10000)
    exact = 2 * math.pi  # E/(1 - rho) = pi * 1 / 0.5
    np.testing.assert_allclose(out["radiosity"], exact, rtol=1e-6)
    np.testing.assert_allclose(out["radiance"], exact / math.pi, rtol=1e-6)
    assert len(out["names"]) == 6 and "energy" in out["report"]


def test_bad_input_is_a_clear_error():
    v, f = unit_cube()
    with pytest.raises(ValueError, match="face 0: vertex index 99 out of range"):
        radiosity.view_factors(v, [[0, 1, 99]])
    with pytest.raises(ValueError, match="unknown"):
        radiosity.view_factors(v, f, method="magic")
    with pytest.raises(ValueError, match=r"\(n, 3\)"):
        radiosity.view_factors(v[:, :2], f)
    with pytest.raises(ValueError, match="no boundary condition"):
        radiosity.exchange(v, f, 0.5, temperature=[300.0, math.nan, 300, 300, 300, 300])
    with pytest.raises(ValueError, match="emissivity"):
        radiosity.exchange(v, f, 1.5, temperature=300.0)
    with pytest.raises(FileNotFoundError, match="no such file"):
        radiosity.load_scene("/nonexistent/scene.obj")


def heavy(n=40):
    """Enough work for a second or more: two n x n grids facing each other."""
    va, fa = grid_plate(n, 0.0, True)
    vb, fb = grid_plate(n, 1.0, False)
    return np.vstack([va, vb]), np.vstack([fa, fb + len(va)])


def test_the_gil_is_released_during_work():
    v, f = heavy()
    done = threading.Event()

    def work():
        radiosity.view_factors(v, f, method="point-sampled", mesh_size=0)
        done.set()

    t = threading.Thread(target=work)
    t.start()
    ticks = 0
    while not done.is_set():
        time.sleep(0.01)
        ticks += 1
    t.join()
    assert ticks >= 5, f"the main thread ran only {ticks} times while the work ran"


def test_ctrl_c_stops_the_work():
    v, f = heavy(60)  # about 5 s of Monte Carlo on two cores

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGALRM, interrupt)
    signal.setitimer(signal.ITIMER_REAL, 0.3)
    t0 = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            radiosity.view_factors(v, f, method="monte-carlo", mesh_size=0)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    assert time.perf_counter() - t0 < 2.0
