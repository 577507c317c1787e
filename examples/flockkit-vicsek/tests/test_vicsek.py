"""How a third-party plugin tests itself: the flockkit conformance kit, plus its own properties."""

import numpy as np

import flockkit
from flockkit.testing import parametrize_with_checks

from flockkit_vicsek import Vicsek


@parametrize_with_checks([("behavior", Vicsek()), ("behavior", Vicsek(noise=0.5, radius=5.0))])
def test_conformance(component, check):
    check(component)


def test_found_through_its_entry_point():
    assert isinstance(flockkit.get("behavior", "vicsek", noise=0.1), Vicsek)


def test_speed_is_constant_after_the_first_step():
    motion = flockkit.simulate("vicsek", n_agents=20, steps=30, seed=1)
    speeds = np.linalg.norm(motion.velocities()[1:], axis=-1)
    np.testing.assert_allclose(speeds, 1.0, rtol=1e-9)
