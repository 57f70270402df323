"""A cell file's rows within their ranges, before they count (--resume) or are summarised (the report), as a
checkpoint's values are checked before a run resumes from them (train/learning/checkpoint_checks.py).

A page checksum proves a file is the one written, not that what was written is a cell's: a file rewritten with NaN,
a negative error or a volume no jar holds, with a valid checksum, would reach the report as `[nan-nan]` or
`-269926862.4 %`. Each column is held to what run_cell can write; the first one out of range is named with its row
and value.
"""

from __future__ import annotations

import math

from sim.objects import ObjectsConfig
from train.learning.checkpoint_checks import MAX_REL_ERROR, PREDICTION_JARS
from train.sweeps.cell import PROPERTY_COLUMNS, RULE_LETTERS, STATE_LETTERS
from train.sweeps.spec import MAX_ORDERS

_C = ObjectsConfig()
# the largest jar an objects file admits (its widest diameter, its tallest height): a rise or an Archimedes volume
# beyond it is no reading of any set
JAR_CM3 = math.pi * (_C.max_jar_diameter_cm / 2) ** 2 * _C.max_jar_height_cm
MAX_OBJECTS = 100_000   # train or probe objects of a set: the generator's limits are 2,000 and 1,000


def _cut(v) -> str:
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


def rows_problem(table) -> str | None:
    """Why the rows (a Table of cell.schema()) are not what run_cell writes, naming the first column out of range,
    its row and its value; None when every column is in range."""
    import numpy as np

    def col(name):
        return table.column(name).to_pylist()

    n_train, n_orders = col("n_train"), col("n_orders")
    ints = {   # column: (its check given the row, what it must be)
        "n_train": (lambda v, i: v is not None and 1 <= v <= MAX_OBJECTS, f"a count of train objects (1 to {MAX_OBJECTS:,})"),
        "n_probe": (lambda v, i: v is not None and 0 <= v <= MAX_OBJECTS, f"a count of probes (0 to {MAX_OBJECTS:,})"),
        "n_orders": (lambda v, i: v is not None and 1 <= v <= MAX_ORDERS, f"a count of orders (1 to {MAX_ORDERS:,})"),
        "order": (lambda v, i: v is not None and 0 <= v < n_orders[i], "an order of the cell (0 to n_orders - 1)"),
        "episode": (lambda v, i: v is not None and 1 <= v <= n_train[i], "an episode of the cell (1 to n_train)"),
        "seed": (lambda v, i: v is not None and v >= 0, "a seed (0 or more)"),
        "generator_seed": (lambda v, i: v is None or v >= 0, "a generator seed (0 or more, or none)"),
        "stored": (lambda v, i: v is not None and 0 <= v <= n_train[i], "a count of stored episodes (0 to n_train)"),
    }
    for name, (ok, what) in ints.items():
        for i, v in enumerate(col(name)):
            if not ok(v, i):
                return f"its column {name} holds {_cut(v)} at row {i}, not {what}"

    def fin(v):
        return v is not None and isinstance(v, float) and math.isfinite(v)

    prediction = PREDICTION_JARS * JAR_CM3
    floats = {
        "observed_cm3": (lambda v, i: fin(v) and abs(v) <= JAR_CM3, f"a rise a jar holds (at most {JAR_CM3:,.0f} cm^3)"),
        "archimedes_cm3": (lambda v, i: fin(v) and 0 < v <= JAR_CM3,
                           f"an object's volume a jar holds (0 to {JAR_CM3:,.0f} cm^3)"),
        "predicted_cm3": (lambda v, i: v is None or (fin(v) and abs(v) <= prediction),
                          f"a prediction (a finite volume within {PREDICTION_JARS:g} jars, or none)"),
        "probe_rel_error": (lambda v, i: v is None or (fin(v) and 0 <= v <= MAX_REL_ERROR),
                            f"a relative error (0 to {MAX_REL_ERROR:g}, or none)"),
        "recalled": (lambda v, i: v is None or (fin(v) and 0 <= v <= n_train[i]),
                     "a count of recalled episodes (0 to n_train, or none)"),
    }
    for name, (ok, what) in floats.items():
        for i, v in enumerate(col(name)):
            if not ok(v, i):
                return f"its column {name} holds {_cut(v)} at row {i}, not {what}"
    for name in ("probe_errors", "probe_floors"):
        for i, vs in enumerate(col(name)):
            if vs is not None and not all(fin(v) and 0 <= v <= MAX_REL_ERROR for v in vs):
                bad = next(v for v in vs if not (fin(v) and 0 <= v <= MAX_REL_ERROR))
                return f"its column {name} holds {_cut(bad)} at row {i}, not a relative error (0 to {MAX_REL_ERROR:g})"
    letters = {"knowledge": (STATE_LETTERS, False, None), "rules": (RULE_LETTERS, False, None),
               "batch_knowledge": (STATE_LETTERS, True, None),
               **{p: (STATE_LETTERS, True, 1) for p in PROPERTY_COLUMNS}}
    for name, (alphabet, nullable, length) in letters.items():
        for i, v in enumerate(col(name)):
            if v is None and nullable:
                continue
            if v is None or not set(v) <= set(alphabet) or (length is not None and len(v) != length):
                return (f"its column {name} holds {_cut(v)} at row {i}, not "
                        f"{'a letter' if length else 'letters'} of {alphabet}{' (or none)' if nullable else ''}")
    for name in ("sank", "goal_reached", "commit", "cell", "condition", "world", "set_group", "set", "object"):
        if table.column(name).null_count:
            i = int(np.flatnonzero(np.asarray(table.column(name).is_null()))[0])
            return f"its column {name} is empty at row {i}"
    return None
