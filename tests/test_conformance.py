"""Every installed component of every kind, built-in or third-party, goes through the conformance kit."""

import flockkit
from flockkit.testing import parametrize_with_checks

# Components that need parameters get ones the kit's inputs can meet (its graph is 2D, near the origin).
PARAMS = {
    ("walk", "region"): {"region": flockkit.Ball(center=[0.0, 0.0], radius=60.0)},
    # the kit's group circles at full speed: its arrows (Features.from_motion) have length 1
    ("walk", "annotated"): {"target": [(0.0, [1.0, 0.0]), (30.0, [0.0, 1.0])]},
}
COMPONENTS = [
    (kind, flockkit.get(kind, name, **PARAMS.get((kind, name), {})))
    for kind in ("behavior", "metric", "builder", "walk", "proposal", "objective", "segmenter")
    for name in flockkit.available(kind)
]


@parametrize_with_checks(COMPONENTS)
def test_installed_plugins_conform(component, check):
    check(component)
