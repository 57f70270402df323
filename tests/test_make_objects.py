"""The seeded object-set generator: valid files, every shape, sinkers and floaters, controlled pairs, same seed same
file, and a CLI that refuses bad input in one line."""

import json
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
