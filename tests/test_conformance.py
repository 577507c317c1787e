"""Every installed behavior model and metric, built-in or third-party, goes through the conformance kit."""

import flockkit
from flockkit.testing import parametrize_with_checks

COMPONENTS = [(kind, flockkit.get(kind, name)) for kind in ("behavior", "metric") for name in flockkit.available(kind)]


@parametrize_with_checks(COMPONENTS)
def test_installed_plugins_conform(component, check):
    check(component)
