"""A sweep's DIR: the cells' Parquet files (written atomically, checked before they count), their provenance
(commit, libraries, host, times, config), DIR/sweep.json and DIR/configs.json (docs/sweeps.md "DIR").

Nothing here runs a cell: the driver (train/sweeps/driver.py) writes what the workers return, --resume surveys what
is there, and the report reads it.
"""

from __future__ import annotations

import json
import stat
from pathlib import Path

from sim.output_files import write_atomic
from train.common.out_checks import link_inside, refuse_uncreatable, refuse_unusable, refuse_unwritable
from train.sweeps import provenance
from train.sweeps.cell import cell_id, config_hash, config_record, schema
from train.sweeps.spec import FORMAT, SweepError, n_orders, read_bounded

ROOT = Path(__file__).resolve().parents[2]
MAX_RECORD_BYTES = 1 << 30      # DIR/sweep.json and DIR/configs.json as this program writes them (the largest
                                # legal sweep, 1,000,000 cells, records well under this; see docs/sweeps.md)

META_KEY = b"aesop_torch.sweep"   # the key of a cell file's provenance in its Parquet metadata


def needs_pyarrow() -> None:
    """SweepError (one line) where pyarrow cannot be imported: every cell is a Parquet file, and a reader that
    failed for that reason would take every good file for a damaged one."""
    try:
        import pyarrow  # noqa: F401
        import pyarrow.parquet  # noqa: F401
    except ImportError as e:
        raise SweepError(f"pyarrow is not installed ({e}): a sweep's cells are Parquet files; install the project's "
                         f"dependencies (pip install -e .)") from None


def cell_metadata(cell: dict, commit: str, info: dict) -> dict:
    """A cell file's provenance (docs/sweeps.md): its id and format, the driver's commit, the worker's libraries,
    host and times, its config's hash and the config itself."""
    record = config_record(cell)
    return {"cell": cell_id(cell), "format": cell["format"], "commit": commit, "versions": provenance.versions(),
            **info, "config": config_hash(record), "config_record": record}


def cell_info(path) -> dict:
    """The provenance a cell file holds (cell_metadata's dict); {} for a file written without it."""
    import pyarrow.parquet as pq
    meta = pq.read_metadata(path).metadata or {}
    return json.loads(meta[META_KEY]) if META_KEY in meta else {}


# -- writing ------------------------------------------------------------------------------------------------------

def encode_cell(table, metadata: dict | None = None) -> bytes:
    """A cell's rows as the bytes of its Parquet file (zstd, a CRC per page, so --resume notices a damaged one),
    with `metadata` (cell_metadata) as JSON under META_KEY."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    if metadata is not None:
        table = table.replace_schema_metadata({META_KEY: json.dumps(metadata, sort_keys=True)})
    buf = pa.BufferOutputStream()
    pq.write_table(table, buf, compression="zstd", write_page_checksum=True)
    return buf.getvalue().to_pybytes()


def write_cell(out: Path, cid: str, table) -> None:
    """A cell's rows (a Table, or encode_cell's bytes) to DIR/cells/<cid>.parquet, atomically."""
    write_atomic(out / "cells" / f"{cid}.parquet", table if isinstance(table, bytes) else encode_cell(table))


def read_cell(path):
    """One cell file's rows (pyarrow Table of `schema()`, without the file's metadata), its pages' CRCs checked."""
    import pyarrow.parquet as pq
    return pq.read_table(path, page_checksum_verification=True).replace_schema_metadata(None)


def read_cells(out: Path, ids=None):
    """Every finished cell's rows under DIR/cells (only the cells named in `ids`, if given), as one pyarrow Table
    (cells in file-name order)."""
    import pyarrow as pa
    files = sorted((Path(out) / "cells").glob("*.parquet"))
    if ids is not None:
        ids = set(ids)
        files = [f for f in files if f.stem in ids]
    if not files:
        return schema().empty_table()
    return pa.concat_tables([read_cell(f) for f in files])


def check_cell_file(path: Path, cell: dict | None = None) -> str | None:
    """Why the file at `path` is not the finished rows of the cell its name says (None: it is). cell: that cell's
    spec, to check the rows against (its condition, set group, set, seed, orders and episodes); without it, only that
    the file reads and its rows are the cell of its name."""
    import numpy as np
    import pyarrow.parquet  # noqa: F401  (a missing pyarrow is no damaged file: needs_pyarrow names it)

    from train.sweeps.row_checks import rows_problem
    try:
        st = path.stat()
        if not stat.S_ISREG(st.st_mode):
            return "not a regular file"
        if st.st_size == 0:
            return "empty (0 bytes)"
        table = read_cell(path)
    except Exception as e:   # noqa: BLE001  pyarrow's reasons are many (ArrowInvalid, OSError, ...)
        import re
        why = (str(e).strip().splitlines() or [type(e).__name__])[0]
        why = re.sub(r"^Could not open Parquet input source '.*?': ", "", why)   # the path is said already
        return f"not a readable Parquet file ({why[:120]})"
    if table.schema != schema():
        return f"its columns are not those of format {FORMAT} (another version of train/sweeps wrote it?)"
    ids = table.column("cell").unique().to_pylist()
    if ids != [path.stem]:
        return (f"holds the rows of cell {ids[0]}, not {path.stem} (renamed?)" if len(ids) == 1 else
                f"holds the rows of {len(ids)} cells" if ids else "holds no rows")
    if why := rows_problem(table):
        return why
    if cell is None:
        return None
    n, B = cell["n_train"], n_orders(cell["orders"], cell["n_train"])
    for column, want in (("condition", cell["condition"]["name"]), ("set_group", cell["set_group"]),
                         ("set", cell["set"]), ("seed", cell["seed"]), ("world", cell["world"])):
        got = table.column(column).unique().to_pylist()
        if got != [want]:
            return f"its rows' {column} is {', '.join(map(str, got[:3]))}, not this cell's {want}"
    if table.num_rows != B * n:
        return f"{table.num_rows} rows, not this cell's {B} order(s) x {n} episodes"
    if not (np.array_equal(table.column("order").to_numpy(), np.repeat(np.arange(B), n)) and
            np.array_equal(table.column("episode").to_numpy(), np.tile(np.arange(1, n + 1), B))):
        return "its rows are not this cell's orders and episodes, order by order"
    return None


def survey(out: Path, cells: list[dict]) -> tuple[set, list[str], list[tuple[Path, str]]]:
    """What DIR/cells holds: (the ids of the cells finished, checked by check_cell_file; the names of foreign files,
    no cell of this sweep; (path, why) of the files of this sweep's cells that are not their finished rows). Skipped:
    a write's temporary files (.<cell>.parquet.*.tmp) and files set aside (*.rejected)."""
    by_id = {c["id"]: c["spec"] for c in cells}
    done, foreign, bad = set(), [], []
    folder = out / "cells"
    if not folder.is_dir():
        return done, foreign, bad
    for path in sorted(folder.iterdir()):
        name = path.name
        if name.startswith(".") or name.endswith(".rejected"):
            continue
        if path.suffix != ".parquet" or path.stem not in by_id:
            foreign.append(name)
            continue
        why = check_cell_file(path, by_id[path.stem])
        if why is None:
            done.add(path.stem)
        else:
            bad.append((path, why))
    return done, foreign, bad


def cell_commits(out: Path, ids) -> dict[str, int]:
    """{commit: cells} of the cells `ids` in DIR/cells, from their rows' commit column (most cells first)."""
    import pyarrow.parquet as pq
    found: dict[str, int] = {}
    for cid in sorted(ids):
        rows = pq.read_table(out / "cells" / f"{cid}.parquet", columns=["commit"])
        for c in rows.column("commit").unique().to_pylist():
            found[c] = found.get(c, 0) + 1
    return dict(sorted(found.items(), key=lambda kv: -kv[1]))


def check_commits(out: Path, done, this: str, allow_mixed: bool) -> dict[str, int]:
    """--resume: SweepError (one line) if the cells on disk (`done`) were written by other code than this checkout's
    (`this`): at another commit, or from a dirty tree (then the commit does not name the code), or by a checkout
    outside git; {} when they were not. With allow_mixed: {commit: cells} of those on disk instead (the driver
    says so, and the report names every commit)."""
    if not done:
        return {}
    found = cell_commits(out, done)
    if list(found) == [this] and provenance.names_its_code(this):
        return {}
    if allow_mixed:
        return found
    written = ", ".join(f"{c} ({n} cell{'s' if n > 1 else ''})" for c, n in found.items())
    if not provenance.names_its_code(this):
        why = (f"this checkout has uncommitted changes ({this})" if this.endswith("-dirty") else
               "this checkout's commit is unknown (not a git checkout?)")
        raise SweepError(f"--resume: {why}, so its cells would not be the same code as the {len(done)} on disk "
                         f"(written at {written}); commit, or --allow-mixed-commits to mix them (the report says so)")
    raise SweepError(f"--resume: the {len(done)} cell(s) on disk were written at {written}, not at this checkout's "
                     f"{this}; check that commit out, sweep into another --out, or --allow-mixed-commits to mix them "
                     f"(the report says so)")


def _first_difference(a, b, where: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in list(a) + [k for k in b if k not in a]:
            if k not in a or k not in b or a[k] != b[k]:
                return _first_difference(a.get(k), b.get(k), f"{where}.{k}" if where else str(k))
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{where} ({len(b)} entries in the sweep file, {len(a)} recorded)"
        for i, (x, y) in enumerate(zip(a, b)):
            if x != y:
                return _first_difference(x, y, f"{where}[{i}]")
    return where or "the spec"


WRITTEN = ("sweep.json", "configs.json", "cells")   # what a sweep writes in DIR


def check_out(out: Path, spec: dict, resume: bool) -> dict | None:
    """Refuse a DIR this sweep may not write (nothing is created here): the checks every --out gets
    (train/common/out_checks.py), and the sweep's own. --resume: the record DIR/sweep.json holds."""
    refuse_unusable(out, SweepError)
    recorded = out / "sweep.json"
    record = None
    if resume:
        if link := link_inside(out, WRITTEN):
            raise SweepError(f"--resume: {link} is a symbolic link; the sweep writes only inside --out {out}: "
                             f"remove it")
        if not recorded.exists():
            raise SweepError(f"--resume: {out} holds no sweep ({recorded} not found)")
        try:
            record = json.loads(read_bounded(recorded, MAX_RECORD_BYTES, "a sweep record"))
            old = record["spec"]
        except SweepError as e:
            raise SweepError(f"--resume: {e}") from None
        except (ValueError, KeyError, TypeError, RecursionError) as e:
            why = "nested too deeply" if isinstance(e, RecursionError) else f"{type(e).__name__}: {e}"
            raise SweepError(f"--resume: cannot read {recorded}: {why}") from None
        if old != json.loads(json.dumps(spec)):
            raise SweepError(f"--resume: {out} holds another sweep ({_first_difference(old, spec)} differs); give "
                             f"another --out")
        if (out / "cells").exists() and not (out / "cells").is_dir():
            raise SweepError(f"--resume: {out / 'cells'} is not a directory")
    elif out.is_dir() and any(out.iterdir()):
        raise SweepError(f"--out {out} already holds files; --resume to continue its sweep, or another --out")
    refuse_uncreatable(out, SweepError)
    refuse_unwritable(out, SweepError)
    return record


def write_record(out: Path, record: dict) -> None:
    """DIR/sweep.json, atomically."""
    write_atomic(out / "sweep.json", (json.dumps(record, indent=1) + "\n").encode())


def write_configs(out: Path, cells: list[dict]) -> None:
    """DIR/configs.json: {config hash: config_record} of every cell of the sweep, with those recorded before (a
    resumed sweep whose code resolves a config otherwise keeps both)."""
    configs = {}
    path = out / "configs.json"
    if path.exists():
        try:
            old = json.loads(read_bounded(path, MAX_RECORD_BYTES, "a configs record"))
            configs = old if isinstance(old, dict) else {}
        except (SweepError, ValueError, RecursionError):
            pass   # damaged: written anew from the cells
    for c in cells:
        record = config_record(c["spec"])
        configs.setdefault(config_hash(record), record)
    write_atomic(path, (json.dumps(configs, indent=1, sort_keys=True) + "\n").encode())

