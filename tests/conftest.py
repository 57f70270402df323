"""Test-wide settings."""

import torch

# Small tensor ops on a 2-core machine run faster on one thread than two fighting each other (measured: up to 100x
# on pytorch-kinematics' FK when the other core is busy). Results do not depend on it.
torch.set_num_threads(1)
