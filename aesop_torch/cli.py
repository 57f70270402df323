"""The console commands of pyproject's [project.scripts]: aesop-run, aesop-sweep, aesop-report and aesop-ask, the
same as `python train/run.py`, `python train/sweep.py`, `python -m train.report` and `python train/ask.py`, from any
directory.

train/ and sim/ are the repository's folders, not installed packages (pyproject.toml says why): each command puts
the repository root (the folder that holds this package, as `pip install -e .` leaves it) on sys.path and calls the
script's main. Self-contained (no relative import), so that it can be loaded from its file.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _main(command: str, module: str, name: str = "main"):
    """module's function `name` (its main), the repository root put first on sys.path; exit code 2 and one line when
    this package is not in its repository (installed without -e: train/ is not beside it). The module is named, not
    imported: the library imports nothing from train/."""
    if not (ROOT / "train" / "__init__.py").is_file():
        print(f"{command}: error: {ROOT} holds no train/: the console commands run from the repository (install it "
              f"with `pip install -e .` there)", file=sys.stderr)
        raise SystemExit(2)
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    return getattr(importlib.import_module(module), name)


def run(argv=None) -> int:
    """aesop-run: train/run.py. As the console command (argv None) it ends as the script does, sparing the
    interpreter's teardown (train.run.console_main)."""
    if argv is None:
        _main("aesop-run", "train.run", "console_main")()
    return _main("aesop-run", "train.run")(argv)


def sweep(argv=None) -> int:
    """aesop-sweep: train/sweep.py (its usage line names aesop-sweep)."""
    return _main("aesop-sweep", "train.sweep")(argv, prog="aesop-sweep")


def report(argv=None) -> int:
    """aesop-report: python -m train.report (its usage line names aesop-report)."""
    return _main("aesop-report", "train.report")(argv, prog="aesop-report")


def ask(argv=None) -> int:
    """aesop-ask: train/ask.py."""
    return _main("aesop-ask", "train.ask")(argv)
