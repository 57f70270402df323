"""The benches' command lines: a bench refuses a count it cannot measure with before it starts (argparse's exit 2,
benches/cli_args.py), every script in benches/ answers --help, and only --record rewrites BENCHMARKS.md."""

import argparse
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from forked_scripts import run_scripts

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


# -- every script in benches/ answers --help and refuses a bad flag, before anything runs --------------------------

SCRIPTS = sorted(p.name for p in BENCHES.glob("*.py"))


def run_script(name: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(BENCHES / name), *args], capture_output=True, text=True, timeout=60,
                          cwd=BENCHES.parent)


@pytest.fixture(scope="module")
def answers() -> dict:
    """Every script's answer to --help and to a bad flag, from one interpreter that forks a child per run
    (tests/forked_scripts.py: each child runs the script as __main__ with its own argv, output and exit code)."""
    runs = [(name, flag) for name in SCRIPTS for flag in ("--help", "--no-such-flag")]
    done = run_scripts([[BENCHES / name, flag] for name, flag in runs], cwd=BENCHES.parent)
    return dict(zip(runs, done))


@pytest.mark.parametrize("name", SCRIPTS)
def test_every_bench_answers_help_and_runs_nothing(name, answers):
    r = answers[name, "--help"]
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert f"usage: {name}" in r.stdout and "-h, --help" in r.stdout


@pytest.mark.parametrize("name", SCRIPTS)
def test_every_bench_refuses_a_bad_flag_in_one_line(name, answers):
    r = answers[name, "--no-such-flag"]
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip().splitlines()[-1] == f"{name}: error: unrecognized arguments: --no-such-flag"


def test_every_recording_bench_records_only_with_record():
    """Each bench that writes BENCHMARKS.md does it through record.run_main (only with --record) and takes the flag."""
    for path in BENCHES.glob("*.py"):
        text = path.read_text()
        if path.name == "record.py":
            continue
        assert "recorded(" not in text, f"{path.name} records without --record"
        if "run_main(" in text:
            assert "record_flag(ap" in text, f"{path.name} does not accept --record"


@pytest.mark.parametrize("name, args", [("memory_capacity.py", ["--throughput", "--record"]),
                                        ("population.py", ["--skip-run", "--record"]),
                                        ("perception.py", ["--seed", "1", "--record"])])
def test_a_partial_run_refuses_record_in_one_line(name, args):
    r = run_script(name, *args)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines()[-1].startswith(f"{name}: error: --record records")


def test_som_bench_answers_help_without_minisom():
    """MiniSom is a benchmark-only dependency: --help needs none, and a run without it ends in one line."""
    path = BENCHES / "som_vs_minisom.py"
    code = ("import runpy, sys; sys.modules['minisom'] = None; sys.path.insert(0, sys.argv[1]); "
            "sys.argv = sys.argv[2:]; runpy.run_path(sys.argv[0], run_name='__main__')")
    r = subprocess.run([sys.executable, "-c", code, str(BENCHES), str(path), "--help"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and "usage: som_vs_minisom.py" in r.stdout, r.stderr
    r = subprocess.run([sys.executable, "-c", code, str(BENCHES), str(path)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines()[-1] == "benches/som_vs_minisom.py needs MiniSom: pip install minisom"


def test_a_bench_run_without_record_leaves_benchmarks_md_as_it_was():
    md = BENCHES.parent / "BENCHMARKS.md"
    before = md.read_bytes()
    r = run_script("trials.py", "--seeds", "1", "--orders", "1", "--sets", "1", "--stands", "1")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1].startswith("first_choice_correct_min=")
    assert "recorded in" not in r.stderr and md.read_bytes() == before
