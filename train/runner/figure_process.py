"""Figure 2 drawn in a process of its own, started before the runner imports torch.

The runner's first second is torch's import, on one core, while the other core idles. A process started then imports
`train.runner.figures` there (matplotlib: ~0.5 s on that core; not torch: the figure's names come from the torch-free
`aesop_torch.names`) and waits, so Figure 2 at the end costs its drawing alone (~0.3 s, beside the goal trials)
instead of an import and a drawing after them. A run with a population (more orders than it runs in detail) runs it
here too (train/runner/loop.py): that process also imports `train.learning.population` (torch) at its start, beside
the runner's own torch import, and draws the population's orders, rather than after the simulations, when the
population is the run's longest part.
It holds no pybullet and no world. It ignores Ctrl-C (the runner owns it and ends the process) and lives until
`close`.
"""

from __future__ import annotations

import importlib

from train.learning.sim_pool import by_name, end_pool, quiet_pool

FIGURES = "train.runner.figures"
POPULATION = "train.learning.population"


def _init(modules: tuple, orders: tuple | None) -> None:
    for module in modules:   # the imports this process exists to take off the runner's critical path
        importlib.import_module(module)
    if orders is not None:   # and the population's orders, drawn and put in a trie meanwhile
        importlib.import_module(POPULATION).prepare_orders(*orders)


POPULATION_FIGURE_KEYS = ("orders", "agree_fraction", "most_common_knowledge", "curves")


def figure_of_the_population(runs, path, dpi: int, floor):
    """Figure 2 with the population this process ran last (train.learning.population.LAST): asked for right after
    the population, it is drawn as soon as the population is done, while the runner takes in the population's answer
    and makes summary.json, instead of after the answer went to the runner and the figure's part of it came back."""
    from train.learning.population import LAST
    from train.runner.figures import save_figure2
    if not LAST:
        raise RuntimeError("no population has run in the figure process")
    return save_figure2(runs, path, dpi, floor, {k: LAST[k] for k in POPULATION_FIGURE_KEYS})


class Drawer:
    def __init__(self, population: tuple | None = None):
        """population: (n_objects, orders, seed) of the population the run will hand this process (its modules
        imported and its orders prepared at the start: train.learning.population.prepare_orders), or None."""
        self._pool = quiet_pool(1, _init, ((FIGURES, POPULATION) if population else (FIGURES,), population))

    def draw(self, target: str, *args):
        """target(*args) there, target given as "module:function": an object whose get() waits for the result."""
        return self._pool.apply_async(by_name, (target, args))

    def close(self) -> None:
        end_pool(self._pool)
        self._pool = None
