"""Sweeps: conditions x object sets x orders x seeds, run as Ray tasks, the rows of every episode in Parquet.

    python train/sweep.py SWEEP.toml [--out DIR] [--resume [--allow-mixed-commits]] [--address ADDR] [--workers N]
    (installed: aesop-sweep SWEEP.toml ...)

The sweep file (docs/sweeps.md) names conditions (a model, its ablations, overrides of its config) and object sets
(objects files, or sets drawn by `sim.make_objects.generate`), each learned in N random orders from each seed. A
cell is one condition on one object set with one seed: all its orders learn side by side as one batched agent (as
benches/ablation.py runs them), and each cell is one Ray task on one core. Each finished cell's rows are written at
once to DIR/cells/<cell>.parquet (a temporary file renamed into place), <cell> a stable hash of everything the cell
computes from; DIR/sweep.json records the resolved sweep. So a Ctrl-C (one line, exit code 130) or a lost machine
leaves every finished cell on disk, and `--resume` runs only the cells not there, refusing in one line a DIR whose
sweep.json records another sweep, or whose cells other code wrote (another commit, a dirty tree) unless
--allow-mixed-commits. A bad sweep file, flag or DIR is refused in one line on stderr, exit code 2, before Ray
starts and before anything is written. A cell that fails is reported in one line; the others go on, and the sweep
ends with exit code 1 (--resume runs the failed cells again).

Without --address a local Ray instance is started on this machine with --workers CPUs (default: its cores) and shut
down at the end, with every process it started; with --address (e.g. `auto` or `HOST:6379`) the sweep joins that
cluster, whose nodes need this repository at the same path and the same Python environment. `aesop-report DIR`
(or `python -m train.report DIR`) summarises the rows.

The parts: train/sweeps/spec.py (the sweep file), cell.py (one cell's rows), store.py (DIR), cluster.py (Ray),
driver.py (from the flags to the exit code).
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from train.sweeps import driver  # noqa: E402
from train.sweeps.spec import SweepError  # noqa: E402


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints usage + message; one line is enough
        raise SweepError(message)


def _count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {n}")
    return n


def parse_args(argv, prog: str = "python train/sweep.py"):
    """The flags; prog: the command as typed, for the usage line. SweepError (one line) for bad ones."""
    ap = _Parser(prog=prog, description=__doc__.split("\n")[0],
                 epilog="The sweep file, DIR and the rows: docs/sweeps.md. Summary: aesop-report DIR.")
    ap.add_argument("sweep", type=Path, metavar="SWEEP.toml", help="the sweep file (TOML, docs/sweeps.md)")
    ap.add_argument("--out", type=Path, metavar="DIR", help="the sweep's directory (default: runs/sweep-<the sweep file's name>)")
    ap.add_argument("--resume", action="store_true", help="run only the cells not yet in DIR/cells (refused if other "
                    "code wrote them: another commit or a dirty tree)")
    ap.add_argument("--allow-mixed-commits", action="store_true", help="with --resume: run the rest even if other "
                    "code wrote the cells on disk; the report names every commit")
    ap.add_argument("--address", metavar="ADDR", help="join this Ray cluster (e.g. auto, HOST:6379) instead of starting one here")
    ap.add_argument("--workers", type=_count, metavar="N", help="CPUs of the local Ray instance (default: this machine's cores)")
    a = ap.parse_args(argv)
    if a.address is not None and a.workers is not None:
        raise SweepError("--workers sizes a local Ray instance; with --address the cluster's CPUs decide")
    if a.allow_mixed_commits and not a.resume:
        raise SweepError("--allow-mixed-commits goes with --resume (a new sweep writes all its cells at one commit)")
    if a.out is None:
        a.out = Path("runs") / f"sweep-{a.sweep.stem}"
    return a


def main(argv=None, on_cell=None, prog: str = "python train/sweep.py") -> int:
    """The command line (and aesop-sweep): 0 done, 2 bad input, 1 a failed cell or write, 130/143/129 a signal.
    on_cell(cell): called after each cell is written (tests); prog: the command as typed, for the usage line."""
    return driver.main(functools.partial(parse_args, prog=prog), sys.argv[1:] if argv is None else list(argv),
                       on_cell, console=argv is None)


if __name__ == "__main__":
    sys.exit(main())
