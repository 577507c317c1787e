"""How a third-party plugin tests itself: the flockkit conformance kit, plus its own properties."""

import numpy as np
import pytest
from flockkit_vicsek import Vicsek

import flockkit
from flockkit.errors import ValidationError
from flockkit.testing import check_plugin, parametrize_with_checks


@parametrize_with_checks([("behavior", Vicsek()), ("behavior", Vicsek(noise=0.5, radius=5.0))])
def test_conformance(component, check):
    check(component)


def test_found_through_its_entry_point():
    assert isinstance(flockkit.get("behavior", "vicsek", noise=0.1), Vicsek)


def test_speed_is_constant_after_the_first_step():
    motion = flockkit.simulate("vicsek", n_agents=20, steps=30, seed=1)
    speeds = np.linalg.norm(motion.velocities()[1:], axis=-1)
    np.testing.assert_allclose(speeds, 1.0, rtol=1e-9)


def test_aligned_flocks_order_and_noisy_ones_do_not():
    """The Vicsek order parameter (the mean unit heading's length) is high at low noise in a dense
    flock and low at high noise: the model's phase transition."""

    def order(noise):
        motion = flockkit.simulate("vicsek", n_agents=40, steps=200, seed=2, noise=noise, radius=3.0)
        step = motion.positions[-1] - motion.positions[-2]
        return float(np.linalg.norm((step / np.linalg.norm(step, axis=1, keepdims=True)).mean(axis=0)))

    assert order(0.05) > 0.9 > 0.5 > order(2.5)


def test_the_declaration_is_what_keeps_3d_away():
    class Undeclared(Vicsek):
        capabilities = flockkit.Capabilities()  # the default: 2D and 3D

    with pytest.raises(AssertionError, match=r"declare it: capabilities = flockkit\.Capabilities\(dims=\(2,\)\)"):
        check_plugin("behavior", Undeclared())
    report = check_plugin("behavior", Vicsek())
    assert "check_forward_shape" in report.passed


def test_3d_is_refused_by_name():
    with pytest.raises(ValidationError, match=r"behavior vicsek handles 2D only \(its Capabilities.dims is \(2,\)\)"):
        flockkit.simulate("vicsek", n_agents=5, steps=3, dims=3)
