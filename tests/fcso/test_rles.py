"""RLES: exact largest empty cap against brute force and closed forms.

Two independent references:

* ``brute``: max over a dense Fibonacci sphere of the nearest-normal distance.
  It never exceeds the true maximum (every sample is a point of the sphere)
  and falls short by at most the sphere's covering radius (the nearest
  distance is 1-Lipschitz), which `test_fibonacci_sphere` bounds.
* ``reference``: for small sets, the nearest distance (dense numpy) at the
  two poles of the circle through EVERY triple of normals, at
  ``±(a+b)/|a+b|`` and a pole of the great circle through EVERY pair, and at
  ``-a``: a superset of the candidates that contains the maximiser, computed
  without a convex hull, KD-tree or the module's dedupe.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.spatial import SphericalVoronoi, cKDTree
from scipy.spatial.transform import Rotation

from fcso.rles import fibonacci_sphere, largest_empty_cap, rles

BRUTE_COUNT = 300_000
#: brute <= exact + this (both are exact nearest distances at sphere points)
ROUNDING = 1e-9
#: exact - brute <= this: above the covering radius of the brute sphere
#: (~0.0047 measured for 300k points, asserted < 0.008 below)
BRUTE_SLACK = 0.02
#: exact vs. the all-triples reference
EXACT = 1e-10


@pytest.fixture(scope="module")
def sphere():
    return fibonacci_sphere(BRUTE_COUNT)


def unit(vectors):
    vectors = np.asarray(vectors, dtype=float)
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def clean(normals):
    """Unit rows, zero rows dropped."""
    normals = np.asarray(normals, dtype=float)
    return unit(normals[np.linalg.norm(normals, axis=1) > 1e-12])


def brute(normals, sphere):
    distances, _ = cKDTree(clean(normals)).query(sphere, workers=-1)
    return float(distances.max())


def nearest(points, normals):
    """Nearest-normal chord distance of each point (dense, no KD-tree)."""
    points = np.atleast_2d(points)
    gaps = np.linalg.norm(points[:, None, :] - clean(normals)[None, :, :], axis=2)
    return gaps.min(axis=1)


def reference(normals):
    """Exact RLES by evaluating a superset of the candidates (small sets only)."""
    n = clean(normals)
    distinct = [n[0]]
    for row in n[1:]:
        if min(np.linalg.norm(row - d) for d in distinct) > 1e-9:
            distinct.append(row)
    n = np.array(distinct)
    if len(n) == 1:
        return 2.0
    candidates = [-n]
    for a, b in itertools.combinations(n, 2):
        pole = np.cross(a, b)
        if np.linalg.norm(pole) < 1e-12:  # antipodal: any perpendicular
            pole = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        candidates.append(unit(pole)[None])
        if np.linalg.norm(a + b) > 1e-12:
            candidates.append(np.array([unit(a + b), -unit(a + b)]))
    triples = np.array(list(itertools.combinations(range(len(n)), 3))).reshape(-1, 3)
    if len(triples):
        a, b, c = n[triples[:, 0]], n[triples[:, 1]], n[triples[:, 2]]
        poles = unit(np.cross(b - a, c - a))
        candidates += [poles, -poles]
    candidates = np.vstack(candidates)
    return float(nearest(candidates, n).max())


def check(normals, sphere, exact=True):
    """rles against brute force (and the triple reference); returns rles."""
    value = rles(normals)
    assert 0.0 <= value <= 2.0
    sampled = brute(normals, sphere)
    assert sampled <= value + ROUNDING
    assert value - sampled <= BRUTE_SLACK
    if exact:
        assert value == pytest.approx(reference(normals), abs=EXACT)
    radius, centre = largest_empty_cap(normals)
    assert radius == value
    assert np.linalg.norm(centre) == pytest.approx(1.0, abs=1e-12)
    assert nearest(centre, normals)[0] == pytest.approx(value, abs=1e-12)
    return value


def circle(angles_deg, latitude_deg=0.0):
    angles = np.radians(np.asarray(angles_deg, dtype=float))
    lat = math.radians(latitude_deg)
    return np.column_stack(
        (math.cos(lat) * np.cos(angles), math.cos(lat) * np.sin(angles), np.full(len(angles), math.sin(lat)))
    )


def random_unit(rng, count):
    return unit(rng.normal(size=(count, 3)))


def tilt(normals, seed):
    """A fixed random rotation, so no configuration is axis-aligned."""
    return Rotation.random(random_state=seed).apply(normals)


# --------------------------------------------------------------------- helpers


def test_fibonacci_sphere():
    assert fibonacci_sphere(0).shape == (0, 3)
    points = fibonacci_sphere(BRUTE_COUNT)
    assert points.shape == (BRUTE_COUNT, 3)
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), 1.0, atol=1e-12)
    probes = random_unit(np.random.default_rng(0), 100_000)
    covering = cKDTree(points).query(probes)[0].max()
    assert covering < 0.008 < BRUTE_SLACK
    assert abs(points.mean(axis=0)).max() < 1e-4


# --------------------------------------------------------------- degenerate


def test_empty_input():
    for empty in ([], np.empty((0, 3)), np.zeros((5, 3))):
        value, centre = largest_empty_cap(empty)
        assert value == 2.0
        assert np.linalg.norm(centre) == pytest.approx(1.0)
        assert rles(empty) == 2.0


def test_invalid_input():
    with pytest.raises(ValueError):
        rles(np.ones((4, 2)))
    with pytest.raises(ValueError):
        rles([[0.0, 0.0, 1.0], [np.nan, 0.0, 1.0]])


def test_one_normal(sphere):
    normals = np.array([[0.3, -0.4, 1.2]] * 7)
    assert check(normals, sphere) == 2.0
    np.testing.assert_allclose(largest_empty_cap(normals)[1], -unit(normals[0]), atol=1e-15)


def test_two_antipodal(sphere):
    for normals in ([[0, 0, 1], [0, 0, -1]], tilt([[0, 0, 2.0], [0, 0, -0.5]], 1)):
        value = check(normals, sphere)
        assert value == pytest.approx(math.sqrt(2.0), abs=1e-15)


@pytest.mark.parametrize("angle", [1.0, 30.0, 90.0, 150.0, 179.0])
def test_two_normals(sphere, angle):
    normals = tilt(circle([0.0, angle]), 2)
    value = check(normals, sphere)
    # best point: the antipode of the arc midpoint, at angle 180 - angle/2
    assert value == pytest.approx(2.0 * math.cos(math.radians(angle) / 4.0), abs=1e-12)


def test_three_normals(sphere):
    rng = np.random.default_rng(3)
    for _ in range(3):
        check(random_unit(rng, 3), sphere)
    check(tilt(circle([0, 120, 240]), 3), sphere)  # regular: poles, sqrt(2)
    assert rles(circle([0, 120, 240])) == pytest.approx(math.sqrt(2.0), abs=1e-12)
    check(tilt(circle([0, 10, 20], latitude_deg=50.0), 4), sphere)


# ------------------------------------------------------------- cocircular


@pytest.mark.parametrize("count", [4, 7, 36])
def test_great_circle_regular(sphere, count):
    normals = tilt(circle(np.arange(count) * 360.0 / count), count)
    value = check(normals, sphere, exact=count < 20)
    assert value == pytest.approx(math.sqrt(2.0), abs=1e-12)  # the poles


def test_great_circle_irregular(sphere):
    rng = np.random.default_rng(5)
    for seed in range(3):
        angles = np.sort(rng.uniform(0.0, 360.0, size=9))
        check(tilt(circle(angles), seed), sphere)


@pytest.mark.parametrize("gap", [200.0, 240.0, 300.0])
def test_great_circle_large_gap(sphere, gap):
    # normals spread over 360 - gap degrees; the middle of the gap beats the poles
    normals = tilt(circle(np.linspace(0.0, 360.0 - gap, 8)), 6)
    value = check(normals, sphere)
    assert value == pytest.approx(2.0 * math.sin(math.radians(gap) / 4.0), abs=1e-12)
    assert value > math.sqrt(2.0)
    centre = largest_empty_cap(normals)[1]
    pole = unit(np.cross(normals[0], normals[1]))
    assert abs(centre @ pole) < 1e-9  # on the great circle


def test_small_circle(sphere):
    # regular ring at latitude 30 degrees: the south pole, sqrt(2 + 2 sin 30)
    normals = circle(np.arange(24) * 15.0, latitude_deg=30.0)
    assert check(normals, sphere) == pytest.approx(math.sqrt(3.0), abs=1e-12)
    assert check(tilt(normals, 7), sphere) == pytest.approx(math.sqrt(3.0), abs=1e-12)
    rng = np.random.default_rng(8)
    for latitude in (30.0, -60.0, 80.0):
        angles = rng.uniform(0.0, 360.0, size=10)
        check(tilt(circle(angles, latitude), 9), sphere)
        # part of a ring: a gap of more than 180 degrees
        check(tilt(circle(np.linspace(0.0, 100.0, 6), latitude), 10), sphere)


def test_nearly_cocircular(sphere):
    rng = np.random.default_rng(11)
    ring = circle(np.arange(12) * 30.0, latitude_deg=30.0)
    for noise in (1e-12, 1e-7, 1e-4):
        normals = tilt(unit(ring + noise * rng.normal(size=ring.shape)), 12)
        assert check(normals, sphere) == pytest.approx(math.sqrt(3.0), abs=10 * noise + 1e-9)


# ----------------------------------------------------------- general position


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("count", [4, 5, 8, 16, 50, 200, 500])
def test_random_normals(sphere, seed, count):
    normals = random_unit(np.random.default_rng(100 * seed + count), count)
    check(normals, sphere, exact=count <= 16)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clustered_cap(sphere, seed):
    # normals within 20 degrees of one direction: the cap is centred near its antipode
    rng = np.random.default_rng(seed)
    axis = unit(rng.normal(size=3))
    normals = unit(axis + math.tan(math.radians(20.0)) * rng.uniform(-1, 1, size=(25, 3)) / math.sqrt(3))
    value = check(normals, sphere)
    assert value > 2.0 * math.cos(math.radians(20.0) / 2.0)
    assert largest_empty_cap(normals)[1] @ axis < -0.9


def test_hemisphere(sphere):
    rng = np.random.default_rng(13)
    normals = random_unit(rng, 15)
    normals[:, 2] = np.abs(normals[:, 2])  # upper hemisphere: the answer is > sqrt(2)
    assert check(normals, sphere) >= math.sqrt(2.0)


def test_duplicates_and_lengths(sphere):
    rng = np.random.default_rng(14)
    base = random_unit(rng, 12)
    rows = base[rng.integers(0, len(base), size=2000)] * rng.uniform(0.01, 100.0, size=(2000, 1))
    rows = np.vstack((rows, np.zeros((10, 3)), base))  # every base normal present at least once
    value = check(rows, sphere, exact=False)
    assert value == pytest.approx(reference(base), abs=EXACT)


def test_six_axis_directions(sphere):
    normals = np.vstack((np.eye(3), -np.eye(3)))
    value = check(normals, sphere)
    assert value == pytest.approx(math.sqrt(2.0 - 2.0 / math.sqrt(3.0)), abs=1e-12)
    np.testing.assert_allclose(abs(largest_empty_cap(normals)[1]), 1.0 / math.sqrt(3.0), atol=1e-12)


def test_cube_corners(sphere):
    # 4 cospherical normals per hull face: the best points are the face centres
    normals = unit(np.array(list(itertools.product((-1.0, 1.0), repeat=3))))
    value = check(normals, sphere)
    assert value == pytest.approx(math.sqrt(2.0 - 2.0 / math.sqrt(3.0)), abs=1e-12)
    check(tilt(normals, 15), sphere)


def test_rotation_invariance():
    rng = np.random.default_rng(16)
    configurations = [
        random_unit(rng, 100),
        circle(rng.uniform(0, 360, 9), 30.0),
        circle(np.linspace(0, 90, 5)),
        np.vstack((np.eye(3), -np.eye(3))),
    ]
    for normals in configurations:
        for seed in range(3):
            rotation = Rotation.random(random_state=seed)
            value, centre = largest_empty_cap(normals)
            turned = rotation.apply(normals)
            assert rles(turned) == pytest.approx(value, abs=1e-12)
            # the turned centre is a maximiser for the turned normals
            assert nearest(rotation.apply(centre), turned)[0] == pytest.approx(value, abs=1e-12)


def test_spherical_voronoi_vertices():
    # the Voronoi vertices never beat the result, and give it exactly when the
    # normals are not in one hemisphere (then no edge point can be the optimum)
    rng = np.random.default_rng(17)
    for count in (10, 100):
        normals = random_unit(rng, count)
        vertices = SphericalVoronoi(normals).vertices
        assert nearest(vertices, normals).max() == pytest.approx(rles(normals), abs=1e-12)
        upper = normals.copy()
        upper[:, 2] = np.abs(upper[:, 2]) + 0.05
        upper = unit(upper)
        assert nearest(SphericalVoronoi(upper).vertices, upper).max() <= rles(upper) + 1e-12
