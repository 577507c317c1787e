"""Shared fixtures. Real captured motion lives in ../shared/data beside the project, never here."""

import os
from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def require_folder(folder: Path) -> Path:
    """`folder` if it exists; else skip, or fail when FLOCKKIT_REQUIRE_SHARED_DATA=1."""
    if not folder.is_dir():
        reason = f"real capture data not found at {folder} (put the shared folder beside the project)"
        if os.environ.get("FLOCKKIT_REQUIRE_SHARED_DATA") == "1":
            pytest.fail(f"FLOCKKIT_REQUIRE_SHARED_DATA=1 but {reason}")
        pytest.skip(reason)
    return folder


def free_impulse_lengths(behavior, n_agents: int, steps: int, seed: int):
    """The lengths of the wander impulses `behavior` infers in a free flock of `n_agents` simulated
    for `steps` (``flockkit.simulate``, boids), (steps - 1, n_agents): what a model-like flock's
    impulses are measured against."""
    import numpy as np

    import flockkit

    free = flockkit.simulate(n_agents=n_agents, steps=steps, seed=seed)
    return np.linalg.norm(behavior.wander_impulses(free)[1:-1], axis=-1)


@pytest.fixture
def fresh_registry():
    """Plugins discovered afresh before and after the test (run-time plugins forgotten)."""
    from flockkit import registry

    registry.reset()
    yield
    registry.reset()


@pytest.fixture(scope="session")
def shared_data():
    """The folder of real captures (see require_folder)."""
    return require_folder(SHARED_DATA)
