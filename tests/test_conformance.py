"""Every installed component of every kind, built-in or third-party, goes through the conformance kit."""

import flockkit
from flockkit.testing import inputs, parametrize_with_checks

WALKER = inputs.walker()
LEFT_LEG = WALKER.skeleton.descendants("leg.L")

# Components that need parameters get ones the kit's inputs can meet (its graph is 2D, near the origin).
PARAMS = {
    ("walk", "region"): {"region": flockkit.Ball(center=[0.0, 0.0], radius=60.0)},
    # the kit's group circles at full speed: its arrows (Features.from_motion) have length 1
    ("walk", "annotated"): {"target": [(0.0, [1.0, 0.0]), (30.0, [0.0, 1.0])]},
    ("controller", "clip"): {"clip": WALKER},
    ("controller", "blend"): {
        "a": flockkit.get("controller", "clip", clip=WALKER),
        "b": flockkit.get("controller", "clip", clip=WALKER, rate=1.3, start=0.4),
        "weight": [[0.0, 0.0], [3.0, 1.0]],
    },
    ("controller", "mask"): {
        "children": [
            flockkit.get("controller", "clip", clip=WALKER),
            flockkit.get("controller", "clip", clip=WALKER, rate=0.7),
        ],
        "masks": [~LEFT_LEG, LEFT_LEG],
    },
    ("controller", "graph-walk"): {"clip": WALKER},
    ("controller", "locomotion"): {
        "clips": [
            flockkit.SkeletalClip(
                skeleton=WALKER.skeleton,
                fps=WALKER.fps,
                rotations=WALKER.rotations[:1],
                translations=WALKER.translations[:1],
                name="idle",
            ),
            WALKER,
        ],  # fmt: skip
        "speeds": [0.0, 1.4],
    },
}
COMPONENTS = [
    (kind, flockkit.get(kind, name, **PARAMS.get((kind, name), {})))
    for kind in ("behavior", "metric", "builder", "walk", "proposal", "objective", "segmenter", "controller")
    for name in flockkit.available(kind)
]
# a configured component declares only what it handles: a region walk the dimension of its region
COMPONENTS.append(("walk", flockkit.get("walk", "region", region=flockkit.Ball(center=[0.0, 0.0, 0.0], radius=60.0))))


@parametrize_with_checks(COMPONENTS)
def test_installed_plugins_conform(component, check):
    check(component)
