"""The library's names that code outside it reads without running a model: the object's properties and the
knowledge states, in their order. Torch-free, so that a process that only draws or reports them (the runner's figure
process, train/runner/figure_process.py) does not import torch (~1 CPU-s) for a few tuples."""

from __future__ import annotations

# the paper's four object properties, in the maps' order
PROPERTIES = ("color", "shape", "size", "weight")
# every object property a map can perceive, in the maps' order: the paper's four or the split five are among them
OBJECT_PROPERTIES = ("color", "shape", "fill", "elongation", "size", "weight")
# a property's causal knowledge, codes 0..3 in this order (aesop_torch/rules.py)
STATES = ("unknown", "likely_irrelevant", "dominant", "irrelevant")


def object_properties(names) -> tuple:
    """The object's properties among `names` (a knowledge dict, a list), in the maps' order: the context's left out."""
    names = set(names)
    return tuple(p for p in OBJECT_PROPERTIES if p in names)
