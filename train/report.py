"""A sweep's summary: novel-object errors with their 95 % intervals (or "n too small" over fewer than 10 object
sets), order agreement and colour's fate per condition, as tables and plots, headed by the commit, versions, dates
and command lines that made the rows.

    aesop-report DIR                  (installed; the same as:)
    python -m train.report DIR        (from the repository's root)
    python /path/to/train/report.py DIR   (from anywhere)

Writes DIR/report.md, DIR/report.csv, DIR/errors.png and DIR/agreement.png (docs/sweeps.md "The report"). A DIR
without finished cells, or with a damaged cell file, is refused in one line, exit code 2. The report itself:
train/sweeps/report.py.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the project importable without installing it
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from train.sweeps.report import ReportError, report  # noqa: E402

PROG = "train.report"   # what its lines start with


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse prints usage + message; one line is enough
        raise ReportError(message)


def parse_args(argv, prog: str):
    ap = _Parser(prog=prog, description=__doc__.split("\n\n")[0].replace("\n", " "),
                 epilog="Reads DIR/cells/*.parquet and DIR/sweep.json as train/sweep.py (aesop-sweep) wrote them; "
                        "every figure, its counts and its interval are described in docs/sweeps.md \"The report\".")
    ap.add_argument("dir", type=Path, help="the sweep's directory (train/sweep.py --out)")
    return ap.parse_args(argv)


def main(argv=None, prog: str | None = None) -> int:
    """The command line (and aesop-report): 0 written, 2 bad input, 1 a write that failed. prog: the command as
    typed, for the usage line (default: aesop-report's other spelling, python -m train.report)."""
    a = None
    try:
        a = parse_args(sys.argv[1:] if argv is None else argv, prog or "python -m train.report")
        report(a.dir, warn=lambda line: print(f"{PROG}: {line}", file=sys.stderr))
    except ReportError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"{PROG}: error: cannot write {e.filename or a.dir}: {e.strerror or e}", file=sys.stderr)
        return 1
    print(f"wrote {a.dir}/report.md, report.csv, errors.png, agreement.png")
    return 0


if __name__ == "__main__":
    sys.exit(main(prog=None if __spec__ is not None else f"python {sys.argv[0]}"))
