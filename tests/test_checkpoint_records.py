"""Forged records (the checksum recomputed, as tests/test_checkpoint_forged.py forges them): every field of an
episode's record and every measurement is type- and range-checked when the checkpoint is read, so none reaches
summary.json, the figure or a crash in --resume."""

import json
import math

import pytest

from test_checkpoint import FakePhysics, argv, fake_physics, paper_file, saved, tree, whole  # noqa: F401 fixtures
from test_checkpoint_forged import forged, refused, write_forged
from train.learning import checkpoint as ck
from train import run as runner


def _record(key, value):
    def edit(s):
        s["experiment"]["records"][0][0][key] = value
    return edit


def _knowledge(edit_one):
    def edit(s):
        edit_one(s["experiment"]["records"][0][0]["knowledge"])
    return edit


def _outcome_measurement(key, value):
    def edit(s):
        s["experiment"]["outcomes"]["red_light_cylinder"]["measurement"][key] = value
    return edit


@pytest.mark.parametrize("edit, words", [
    # a NaN would be written to summary.json as a bare NaN (not JSON); a string in a number's place reaches it too
    (_record("predicted_cm3", math.nan), "predicted_cm3 'nan' is not a prediction"),
    (_record("predicted_cm3", "365"), "predicted_cm3 '365' is not a prediction"),
    (_record("predicted_cm3", 1e300), "is not a prediction"),
    (_record("observed_cm3", math.inf), "observed_cm3 'inf' is not a volume the jar holds"),
    (_record("probe_rel_error", -1.0), "probe_rel_error '-1.0' is not a relative error"),
    (_record("goal_reached", "yes"), "goal_reached 'yes' is not true or false"),
    (_record("perceived", {"rgb": [0.5] * 3, "extent_cm": [5.0] * 3, "fill": 0.5, "mass_g": math.nan}),
     "perceived: not a measurement"),
    (_record("\x1b[31mred", 1), r"unexpected '\x1b[31mred'"),
    (_record("true", {"\x1b[2J": 1.0}), "true is not the file's values"),
    # the knowledge the figure and the table read: a property missing, a state no rule gives, a certainty out of 0..1
    (_knowledge(lambda k: k.pop("weight")), "knowledge and rules must name the same properties"),
    (_knowledge(lambda k: k["color"].update(state="bogus")), "knowledge of 'color' is not a state"),
    (_knowledge(lambda k: k["color"].update(certainty=2.0)), "knowledge of 'color' is not a state"),
    (_knowledge(lambda k: k.update({"\x1b[31m": {"state": "unknown", "certainty": 0.0}})),
     "knowledge and rules must name the same properties"),
    (_record("rules", {"color": "X", "shape": "S", "size": "S", "weight": "S"}), "rules of 'color': 'X'"),
    # measurements an object the objects file admits cannot give, which crashed --resume in the encoders
    (_outcome_measurement("fill", 1e-300), "fill 1e-300 outside [0.25, 1]"),
    (_outcome_measurement("mass_g", 1e300), "mass_g 1e+300 above 10000 g"),
    (_outcome_measurement("extent_cm", [1e-300, 5.0, 5.0]), "extent_cm"),
    (lambda s: s["experiment"]["outcomes"]["red_light_cylinder"].update(true={"x": [[[[1.0]]]]}),
     "outcome of 'red_light_cylinder': true is not the file's values"),
])
def test_a_forged_record_is_refused_in_one_line(saved, tmp_path, edit, words):
    message = refused(forged(saved, tmp_path, edit), words)
    assert message.isprintable(), message


def test_the_real_records_pass(saved):
    """The oracle for the bounds: a real run's records (the closed-form stand-in's) are all accepted."""
    state = ck.load(saved[0])
    rec = state["experiment"]["records"][0][0]
    assert {"predicted_cm3", "knowledge", "perceived"} <= set(rec)


@pytest.mark.parametrize("edit", [_knowledge(lambda k: k.pop("weight")), _outcome_measurement("mass_g", 1e300)])
def test_resume_refuses_a_forged_record_with_exit_2_and_changes_nothing(paper_file, whole, tmp_path, capsys, edit):
    """Each resumed before (a KeyError's traceback; a run that went on with a 1e300 g object): now one line."""
    out = tmp_path / "forged"
    for p in whole.rglob("*"):
        if p.is_file():
            (out / p.relative_to(whole)).parent.mkdir(parents=True, exist_ok=True)
            (out / p.relative_to(whole)).write_bytes(p.read_bytes())
    ckpt = out / "checkpoints" / "latest.pt"
    state = ck.load(ckpt)
    edit(state)
    write_forged(state, ckpt)
    before = tree(out)
    assert runner.main(argv(paper_file, out, "--resume")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--resume" in err[0] and "latest.pt" in err[0], err
    assert tree(out) == before


def test_summary_json_is_valid_json_whatever_a_number_is(whole):
    """The whole run's summary.json parses as strict JSON (no NaN, no Infinity)."""
    text = (whole / "summary.json").read_text()
    json.loads(text, parse_constant=lambda c: pytest.fail(f"summary.json holds {c}"))
