"""benches/record.py: a finished bench replaces its own block in BENCHMARKS.md; a failed one changes nothing."""

import importlib.util
from pathlib import Path

import pytest

spec = importlib.util.spec_from_file_location("record", Path(__file__).resolve().parents[1] / "benches" / "record.py")
record = importlib.util.module_from_spec(spec)
spec.loader.exec_module(record)

HEAD = "# Benchmarks\n\nhand-written table\n"


def test_first_run_appends_a_block_and_later_runs_replace_only_theirs(tmp_path, capsys):
    md = tmp_path / "BENCHMARKS.md"
    md.write_text(HEAD)
    with record.recorded("alpha", md):
        print("alpha_rate=1")
    with record.recorded("beta", md):
        print("beta_rate=2")
    with record.recorded("alpha", md):
        print("alpha_rate=3")
    text = md.read_text()
    assert text.startswith(HEAD) and text.count(record.SECTION) == 1
    assert "alpha_rate=3" in text and "alpha_rate=1" not in text and "beta_rate=2" in text
    assert text.index("<!-- bench:alpha -->") < text.index("<!-- bench:beta -->")   # replaced in place
    assert text.count("<!-- /bench:alpha -->") == 1
    # the bench still prints everything, and its last stdout line stays its name=value line
    assert capsys.readouterr().out.splitlines()[-1] == "alpha_rate=3"


def test_a_failed_run_leaves_the_file_as_it_was(tmp_path):
    md = tmp_path / "BENCHMARKS.md"
    md.write_text(HEAD)
    with record.recorded("alpha", md):
        print("alpha_rate=1")
    before = md.read_text()
    with pytest.raises(RuntimeError):
        with record.recorded("alpha", md):
            print("alpha_rate=999")
            raise RuntimeError("bench crashed half way")
    assert md.read_text() == before
    assert list(tmp_path.iterdir()) == [md]   # no temporary file left behind


def test_an_unclosed_block_is_refused():
    with pytest.raises(ValueError, match="no closing"):
        record.replace_block("x\n<!-- bench:alpha -->\nold\n", "alpha", "new")


def test_a_disabled_record_prints_but_writes_nothing(tmp_path, capsys):
    md = tmp_path / "BENCHMARKS.md"
    md.write_text(HEAD)
    with record.recorded("alpha", md, enabled=False):
        print("alpha_rate=0")
    assert md.read_text() == HEAD and capsys.readouterr().out == "alpha_rate=0\n"


def bench_main():
    print("alpha_rate=5")


@pytest.mark.parametrize("argv, written", [([], False), (["--sets", "1"], False), (["--record"], True),
                                           (["--sets", "1", "--rec"], True)])   # argparse's prefix for --record
def test_run_main_records_only_with_record(tmp_path, monkeypatch, capsys, argv, written):
    md = tmp_path / "BENCHMARKS.md"
    md.write_bytes(HEAD.encode())
    monkeypatch.setattr("sys.argv", ["benches/alpha.py", *argv])
    record.run_main("alpha", bench_main, md)
    assert capsys.readouterr().out == "alpha_rate=5\n"   # printed either way
    assert ("alpha_rate=5" in md.read_text()) == written
    if not written:
        assert md.read_bytes() == HEAD.encode() and list(tmp_path.iterdir()) == [md]


def test_run_main_records_nothing_when_main_stops(tmp_path, monkeypatch):
    """--help or a bad flag with --record: argparse exits inside main(), nothing is written."""
    md = tmp_path / "BENCHMARKS.md"
    md.write_text(HEAD)
    monkeypatch.setattr("sys.argv", ["benches/alpha.py", "--record", "--help"])

    def main():
        print("usage: alpha.py [-h] [--record]")
        raise SystemExit(0)
    with pytest.raises(SystemExit):
        record.run_main("alpha", main, md)
    assert md.read_text() == HEAD
