"""argparse types for the benches' counts and seeds: a bad value is one line from argparse (exit 2), never a
traceback halfway through a run (e.g. `--sets 0` dividing by zero sets after minutes of work); and the flag every
recording bench takes, --record. A module the benches import: `python benches/cli_args.py` does nothing."""

from __future__ import annotations

import argparse


def at_least(low: int):
    """An argparse type: a whole number >= low."""
    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if n < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {n}")
        return n
    parse.__name__ = f"whole number >= {low}"
    return parse


count = at_least(1)   # sets, seeds, orders, runs: at least one, or there is nothing to measure
seed = at_least(0)    # numpy's generators take no negative seed


def record_flag(ap: argparse.ArgumentParser, what: str = "BENCHMARKS.md") -> None:
    """--record (benches/record.py run_main): only with it does a bench rewrite its tracked output."""
    ap.add_argument("--record", action="store_true",
                    help=f"write the output into {what} (tracked; without --record no tracked file is written)")


if __name__ == "__main__":
    argparse.ArgumentParser(description="argparse types for the benches: a module they import, nothing to run."
                            ).parse_args()
