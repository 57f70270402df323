"""benches/cli_args.py: a bench refuses a count it cannot measure with before it starts (argparse's exit 2)."""

import argparse
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

BENCHES = Path(__file__).resolve().parents[1] / "benches"
spec = importlib.util.spec_from_file_location("cli_args", BENCHES / "cli_args.py")
cli_args = importlib.util.module_from_spec(spec)
spec.loader.exec_module(cli_args)


def test_counts_and_seeds():
    assert cli_args.count("3") == 3 and cli_args.seed("0") == 0 and cli_args.at_least(8)("230") == 230
    for parse, text in ((cli_args.count, "0"), (cli_args.seed, "-1"), (cli_args.at_least(8), "5"),
                        (cli_args.count, "two"), (cli_args.count, "1.5")):
        with pytest.raises(argparse.ArgumentTypeError):
            parse(text)


def test_a_bench_refuses_zero_sets_in_one_line_and_records_nothing():
    md = BENCHES.parent / "BENCHMARKS.md"
    before = md.read_text()
    r = subprocess.run([sys.executable, str(BENCHES / "trials.py"), "--sets", "0"], capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines()[-1].endswith("argument --sets: must be >= 1, got 0")
    assert md.read_text() == before
