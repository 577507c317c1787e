import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import flockkit
from flockkit.errors import ValidationError

REGIONS = [
    flockkit.Ball(center=[1.0, 2.0], radius=1.5),
    flockkit.Ball(center=[0.0, 0.0, 1.0], radius=2.0),
    flockkit.Box(lower=[-1.0, -2.0], upper=[3.0, 1.0]),
    flockkit.Box(lower=[-1.0, -1.0, 0.0], upper=[1.0, 2.0, 3.0]),
    flockkit.Polygon(vertices=[[0, 0], [4, 0], [4, 3], [2, 1], [0, 3]]),  # not convex
    flockkit.Polygon(vertices=[[0, 0], [0, 2], [2, 2], [2, 0]]),  # clockwise
]


def test_known_distances():
    ball, box, arrow = REGIONS[0], REGIONS[2], REGIONS[4]
    np.testing.assert_allclose(ball.signed_distance([[1.0, 2.0], [4.0, 2.0]]), [-1.5, 1.5])
    np.testing.assert_allclose(box.signed_distance([[0.0, 0.0], [5.0, 0.0], [5.0, 3.0]]), [-1.0, 2.0, np.hypot(2, 2)])
    np.testing.assert_allclose(box.surface_normal([[0.0, 0.5], [5.0, 0.0]]), [[0, 1], [1, 0]])
    assert arrow.contains([[1.0, 2.0], [3.0, 2.0], [2.0, 2.0], [2.0, 0.5]]).tolist() == [True, True, False, True]
    np.testing.assert_allclose(arrow.signed_distance([[2.0, -1.0]]), [1.0])


@pytest.mark.parametrize("region", REGIONS, ids=lambda r: f"{type(r).__name__}{r.dims}d")
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_normal_is_the_gradient_of_signed_distance(region, data):
    point = data.draw(hnp.arrays("float64", region.dims, elements=st.floats(-6, 6)))
    distance = region.signed_distance(point)
    normal = region.surface_normal(point)
    assert np.linalg.norm(normal) == pytest.approx(1.0)
    assert bool(region.contains(point)) == (distance <= 0)
    step = 1e-6
    moved = region.signed_distance(point + step * normal)
    # Along the normal the distance grows at unit rate, except across a crease of the distance field.
    assert moved - distance <= step * (1 + 1e-3)


def test_shapes_of_results():
    box = REGIONS[3]
    points = np.zeros((4, 5, 3))
    assert box.signed_distance(points).shape == (4, 5)
    assert box.surface_normal(points).shape == (4, 5, 3)
    with pytest.raises(ValidationError, match="shape"):
        box.signed_distance(np.zeros((4, 2)))


@pytest.mark.parametrize(
    "build, field",
    [
        (lambda: flockkit.Ball(center=[0, 0, 0, 0], radius=1), "Ball.center"),
        (lambda: flockkit.Ball(center=[0, 0], radius=0), "Ball.radius"),
        (lambda: flockkit.Box(lower=[0, 0], upper=[1, 0]), "Box.lower"),
        (lambda: flockkit.Box(lower=[0, 0], upper=[1, 1, 1]), "Box.lower"),
        (lambda: flockkit.Polygon(vertices=[[0, 0], [1, 1]]), "Polygon.vertices"),
        (lambda: flockkit.Polygon(vertices=[[0, 0], [1, 1], [2, 2]]), "Polygon.vertices"),
        (lambda: flockkit.Polygon(vertices=[[0, 0], [2, 2], [2, 0], [0, 2]]), "Polygon.vertices"),
        (lambda: flockkit.Polygon(vertices=[[0, 0], [np.nan, 1], [1, 0]]), "Polygon.vertices"),
    ],
)
def test_regions_reject_bad_input(build, field):
    with pytest.raises(ValidationError, match=field.replace(".", r"\.")):
        build()
