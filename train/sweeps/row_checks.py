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


def _first(bad) -> int | None:
    """The first True of a boolean array, or None."""
    import numpy as np
    hits = np.flatnonzero(bad)
    return int(hits[0]) if hits.size else None


def rows_problem(table) -> str | None:
    """Why the rows (a Table of cell.schema()) are not what run_cell writes, naming the first column out of range,
    its row and its value; None when every column is in range. Vectorised: a large sweep's report checks every
    cell's rows."""
    import numpy as np
    import pyarrow.compute as pc

    def num(name):   # (values as float64 with NaN for null, null mask)
        c = table.column(name)
        return c.cast("float64").to_numpy(zero_copy_only=False), np.asarray(c.is_null())

    def said(name, i, what):
        return f"its column {name} holds {_cut(table.column(name)[i].as_py())} at row {i}, not {what}"

    n_train, _ = num("n_train")
    n_orders, _ = num("n_orders")
    with np.errstate(invalid="ignore"):   # NaN compares False: a NaN fails every range below
        ints = {   # column: (the bad rows given values v and nulls z, what it must be)
            "n_train": (lambda v, z: z | ~((v >= 1) & (v <= MAX_OBJECTS)),
                        f"a count of train objects (1 to {MAX_OBJECTS:,})"),
            "n_probe": (lambda v, z: z | ~((v >= 0) & (v <= MAX_OBJECTS)), f"a count of probes (0 to {MAX_OBJECTS:,})"),
            "n_orders": (lambda v, z: z | ~((v >= 1) & (v <= MAX_ORDERS)), f"a count of orders (1 to {MAX_ORDERS:,})"),
            "order": (lambda v, z: z | ~((v >= 0) & (v < n_orders)), "an order of the cell (0 to n_orders - 1)"),
            "episode": (lambda v, z: z | ~((v >= 1) & (v <= n_train)), "an episode of the cell (1 to n_train)"),
            "seed": (lambda v, z: z | ~(v >= 0), "a seed (0 or more)"),
            "generator_seed": (lambda v, z: ~z & ~(v >= 0), "a generator seed (0 or more, or none)"),
            "stored": (lambda v, z: z | ~((v >= 0) & (v <= n_train)), "a count of stored episodes (0 to n_train)"),
        }
        prediction = PREDICTION_JARS * JAR_CM3
        floats = {
            "observed_cm3": (lambda v, z: z | ~(np.abs(v) <= JAR_CM3),
                             f"a rise a jar holds (at most {JAR_CM3:,.0f} cm^3)"),
            "archimedes_cm3": (lambda v, z: z | ~((v > 0) & (v <= JAR_CM3)),
                               f"an object's volume a jar holds (0 to {JAR_CM3:,.0f} cm^3)"),
            "predicted_cm3": (lambda v, z: ~z & ~(np.abs(v) <= prediction),
                              f"a prediction (a finite volume within {PREDICTION_JARS:g} jars, or none)"),
            "probe_rel_error": (lambda v, z: ~z & ~((v >= 0) & (v <= MAX_REL_ERROR)),
                                f"a relative error (0 to {MAX_REL_ERROR:g}, or none)"),
            "recalled": (lambda v, z: ~z & ~((v >= 0) & (v <= n_train)),
                         "a count of recalled episodes (0 to n_train, or none)"),
        }
        for name, (bad, what) in {**ints, **floats}.items():
            if (i := _first(bad(*num(name)))) is not None:
                return said(name, i, what)
        for name in ("probe_errors", "probe_floors"):
            c = table.column(name)
            flat = pc.list_flatten(c).cast("float64").to_numpy(zero_copy_only=False)
            bad = ~((flat >= 0) & (flat <= MAX_REL_ERROR))
            if (j := _first(bad)) is not None:
                row = int(np.searchsorted(np.cumsum(pc.fill_null(pc.list_value_length(c), 0).to_numpy()), j,
                                          side="right"))
                return (f"its column {name} holds {_cut(float(flat[j]))} at row {row}, not a relative error (0 to "
                        f"{MAX_REL_ERROR:g})")
    letters = {"knowledge": (STATE_LETTERS, False, None), "rules": (RULE_LETTERS, False, None),
               "batch_knowledge": (STATE_LETTERS, True, None),
               **{p: (STATE_LETTERS, True, 1) for p in PROPERTY_COLUMNS}}
    for name, (alphabet, nullable, length) in letters.items():
        c = table.column(name)
        ok = pc.match_substring_regex(c, f"^[{alphabet}]{{{length}}}$" if length else f"^[{alphabet}]*$")
        bad = ~np.asarray(pc.fill_null(ok, nullable))
        if (i := _first(bad)) is not None:
            what = f"{'a letter' if length else 'letters'} of {alphabet}{' (or none)' if nullable else ''}"
            return said(name, i, what)
    for name in ("sank", "goal_reached", "commit", "cell", "condition", "world", "set_group", "set", "object"):
        if (i := _first(np.asarray(table.column(name).is_null()))) is not None:
            return f"its column {name} is empty at row {i}"
    return None
