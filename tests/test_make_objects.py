"""The seeded object-set generator: valid files, every shape, sinkers and floaters, controlled pairs, same seed same
file, and a CLI that refuses bad input in one line."""

import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from sim.make_objects import _sinks, generate, main
from sim.objects import parse_objects

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("seed", range(20))
def test_every_set_loads_and_holds_every_shape_sinkers_and_floaters(seed):
    for n_train, pairs, jar in ((8, True, "random"), (8, False, "default"), (24, True, "random")):
        data = generate(seed, n_train, 8, pairs, jar)
        objs = parse_objects(data)                       # validated by the objects file's own rules
        assert len(objs.train) == n_train and len(objs.probe) == 8
        assert {o.shape for o in objs.train} == {"cylinder", "cube", "sphere", "box"}
        sinkers = sum(o.sinks for o in objs.train)
        assert min(sinkers, n_train - sinkers) >= 2
        assert all(o.mass_g >= 5.0 for o in objs.train + objs.probe)


def differing(a: dict, b: dict) -> set:
    return {k for k in ("shape", "color", "dims_cm", "mass_g") if a[k] != b[k]}


def test_pairs_change_one_property_each():
    for seed in range(10):
        train = generate(seed, 12, 4, pairs=True)["train"]
        changes = [differing(a, b) for i, a in enumerate(train) for b in train[i + 1:]]
        for one in ({"color"}, {"mass_g"}, {"dims_cm"}):
            assert one in changes, (seed, one)
        # the shape pair: same side and mass, another shape (dims differ in count for a cylinder)
        assert any(c <= {"shape", "dims_cm"} and "shape" in c for c in changes)
        weight_pair = [(a, b) for i, a in enumerate(train) for b in train[i + 1:] if differing(a, b) == {"mass_g"}]
        assert any(_sinks(a) != _sinks(b) for a, b in weight_pair)   # a floater and a sinker of the same look


def test_same_seed_same_file_and_seeds_differ():
    assert json.dumps(generate(3)) == json.dumps(generate(3))
    assert generate(3) != generate(4)


def test_cli_writes_a_file_and_refuses_bad_input(tmp_path, capsys):
    out = tmp_path / "set.json"
    assert main(["--seed", "7", "--train", "8", "--probe", "8", "--pairs", "--out", str(out)]) == 0
    assert parse_objects(json.loads(out.read_text())).train
    assert main(["--seed", "7", "--train", "3"]) == 2
    assert "error" in capsys.readouterr().err
    r = subprocess.run([sys.executable, "-m", "sim.make_objects", "--seed", "1"], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and json.loads(r.stdout)["train"]


def cli(*args, cwd=ROOT):
    r = subprocess.run([sys.executable, "-m", "sim.make_objects", *args], cwd=cwd, capture_output=True, text=True,
                       timeout=60, env={**os.environ, "PYTHONPATH": str(ROOT)})
    return r.returncode, r.stdout, r.stderr.strip().splitlines()


@pytest.mark.parametrize("args, words", [
    (["--seed", "x"], "invalid int value"),
    ([], "required: --seed"),
    (["--seed", "1", "--bogus"], "unrecognized arguments"),
    (["--seed", "1", "--jar", "huge"], "invalid choice"),
    (["--seed", "1", "--train", "2001"], "4..2000"),            # more than an objects file holds
])
def test_cli_flag_errors_are_one_line_with_exit_2(args, words):
    code, out, err = cli(*args)
    assert code == 2 and out == "" and len(err) == 1 and words in err[0] and "usage" not in err[0], err


def test_cli_out_refuses_a_directory_a_missing_parent_and_anything_not_a_regular_file(tmp_path):
    for out, words in [(tmp_path, "is a directory"), (tmp_path / "nope" / "set.json", "does not exist"),
                       (Path("/dev/null"), "not a regular file"), (tmp_path / "f.json" / "x.json", "not a directory")]:
        (tmp_path / "f.json").write_text("{}")
        code, _, err = cli("--seed", "1", "--out", str(out), "--force")
        assert code == 2 and len(err) == 1 and words in err[0], (out, err)
    assert not (tmp_path / "nope").exists() and (tmp_path / "f.json").read_text() == "{}"


def test_cli_out_never_overwrites_unless_forced_and_never_follows_a_link(tmp_path):
    out = tmp_path / "set.json"
    out.write_text("mine")
    code, _, err = cli("--seed", "1", "--out", str(out))
    assert code == 2 and len(err) == 1 and "--force" in err[0] and out.read_text() == "mine"
    code, _, err = cli("--seed", "1", "--out", str(out), "--force")
    assert code == 0 and err == [] and parse_objects(json.loads(out.read_text())).train
    dangling = tmp_path / "dangling.json"
    dangling.symlink_to(tmp_path / "elsewhere.json")
    linked = tmp_path / "linked.json"
    linked.symlink_to(out)
    before = out.read_text()
    for link in (dangling, linked):
        for force in ([], ["--force"]):
            code, _, err = cli("--seed", "2", "--out", str(link), *force)
            assert code == 2 and len(err) == 1 and "symbolic link" in err[0], err
    assert not (tmp_path / "elsewhere.json").exists() and out.read_text() == before and linked.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling.json", "linked.json", "set.json"]  # no temp


def test_cli_writes_a_whole_file_as_an_ordinary_file_would_be(tmp_path):
    out = tmp_path / "set.json"
    code, _, err = cli("--seed", "5", "--out", "set.json", cwd=tmp_path)     # a bare name: the current directory
    assert code == 0 and err == []
    code, stdout, _ = cli("--seed", "5")
    assert out.read_text() == stdout                                           # the same bytes as to stdout
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ["set.json"]
