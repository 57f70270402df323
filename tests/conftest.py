"""Test-wide settings."""

import pytest
import torch

# Small tensor ops on a 2-core machine run faster on one thread than two fighting each other (measured: up to 100x
# on pytorch-kinematics' FK when the other core is busy). Results do not depend on it.
torch.set_num_threads(1)


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray instance (2 CPUs) per test module that asks for it: starting one takes seconds."""
    import ray

    from train import sweep
    started = sweep.start_ray(None, 2)
    yield
    if started:
        ray.shutdown()
