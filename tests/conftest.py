"""Test-wide settings."""

import pytest
import torch

# Small tensor ops on a 2-core machine run faster on one thread than two fighting each other (measured: up to 100x
# on pytorch-kinematics' FK when the other core is busy). Results do not depend on it.
torch.set_num_threads(1)

# Modules that start Ray (a local instance in this process, or a sweep's own in a subprocess): under pytest-xdist
# (pyproject's `-n 2 --dist loadgroup`) they run on one worker, one after another, so that two Ray instances (each
# a dozen processes and its object store) never start side by side on a small machine.
RAY_MODULES = ("test_sweep.py", "test_bench_sweeps.py")


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in RAY_MODULES or "local_ray" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.xdist_group("ray"))


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray instance (2 CPUs) per test module that asks for it: starting one takes seconds."""
    import ray

    from train.sweeps import cluster
    started = cluster.start_ray(None, 2)
    yield
    if started:
        ray.shutdown()
