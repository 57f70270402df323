"""train/run.py refuses bad input with one line on stderr, exit code 2, and writes nothing."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GOOD = {"name": "red_heavy_cylinder", "shape": "cylinder", "color": "red", "dims_cm": [6.36, 11.5], "mass_g": 420}


def run(*args, cwd=None):
    return subprocess.run([sys.executable, str(ROOT / "train" / "run.py"), *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


def refused(tmp_path, objects_text, *words):
    f = tmp_path / "objects.json"
    f.write_text(objects_text)
    out = tmp_path / "out"
    r = run("--objects", str(f), "--out", str(out))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1, r.stderr
    for w in words:
        assert w in lines[0], lines[0]
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert not out.exists()  # nothing written
    return lines[0]


def obj(**kw):
    return {**GOOD, **kw}


@pytest.mark.parametrize("train, words", [
    ([obj(shape="pyramid")], ["red_heavy_cylinder", "shape"]),
    ([obj(dims_cm=[6.36])], ["red_heavy_cylinder", "dims_cm"]),
    ([obj(mass_g=0)], ["red_heavy_cylinder", "mass_g"]),
    ([obj(mass_g=-3)], ["red_heavy_cylinder", "mass_g"]),
    ([obj(dims_cm=[20.0, 5.0])], ["red_heavy_cylinder", "dims_cm"]),      # wider than the jar
    ([obj(), obj()], ["red_heavy_cylinder", "name"]),                     # duplicate names
    ([obj(color="octarine")], ["red_heavy_cylinder", "color"]),
    ([obj(color=[1.2, 0, 0])], ["red_heavy_cylinder", "color"]),
])
def test_bad_object_is_refused(tmp_path, train, words):
    refused(tmp_path, json.dumps({"train": train}), *words)


def test_malformed_json_is_refused(tmp_path):
    refused(tmp_path, '{"train": [', "JSON")


def test_non_finite_number_is_refused(tmp_path):
    refused(tmp_path, '{"train": [{"name": "a", "shape": "cube", "color": "red", "dims_cm": [1e999], "mass_g": 5}]}',
            "a", "dims_cm")


def test_water_deeper_than_jar_is_refused(tmp_path):
    jar = {"inner_diameter_cm": 12.0, "height_cm": 20.0, "water_depth_cm": 25.0}
    refused(tmp_path, json.dumps({"jar": jar, "train": [GOOD]}), "jar", "water_depth_cm")


def test_bad_flags_are_refused(tmp_path):
    for args in (["--orders", "zero"], ["--orders", "0"], ["--seed", "-1"], ["--resume"], ["--bogus"]):
        r = run(*args, "--out", str(tmp_path / "o"))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (args, r.stderr)
        assert not (tmp_path / "o").exists()


def test_resume_without_checkpoint_and_occupied_out_are_refused(tmp_path):
    r = run("--out", str(tmp_path / "none"), "--resume")
    assert r.returncode == 2 and "no checkpoint" in r.stderr
    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "summary.json").write_text("{}")
    r = run("--out", str(occupied))
    assert r.returncode == 2 and "already holds" in r.stderr
    assert (occupied / "summary.json").read_text() == "{}"  # an earlier run is never damaged


def test_gui_without_a_display_is_refused_instead_of_hanging(tmp_path, monkeypatch):
    # pybullet's GUI with no X display does not fail, it hangs: the runner must say so before anything is written
    monkeypatch.delenv("DISPLAY", raising=False)
    r = run("--gui", "--out", str(tmp_path / "o"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "DISPLAY" in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()
