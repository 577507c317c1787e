"""Every installed behavior model, built-in or third-party, goes through the conformance kit."""

import flockkit
from flockkit.testing import parametrize_with_checks

COMPONENTS = [("behavior", flockkit.get("behavior", name)) for name in flockkit.available("behavior")]


@parametrize_with_checks(COMPONENTS)
def test_installed_plugins_conform(component, check):
    check(component)
