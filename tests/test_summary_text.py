"""summary.json's text: train.runner.summary.summary_text writes what json.dumps(summary, indent=1) writes, faster."""

import json
import math

import pytest

from train.runner.summary import summary_text


def summary(keys, errors, **more):
    return {"seed": 0, "runs": [{"order": ["a", "b"], "episodes": [{"x": 1.5, "y": None}]}],
            "order_independent": False, **more,
            "population": {"orders": len(keys), "key": "U unknown", "final_knowledge": keys,
                           "final_probe_rel_error": errors, "agree_fraction": 0.5}}


@pytest.mark.parametrize("keys, errors", [
    (["IIDD", "IIDU", "IIDD"], [0.2973, None, 1e-05]),
    (['q"uote', "back\\slash", "new\nline", "caf\u00e9 \u2603", ""], [0.1, 2.0, -0.0, 3, True]),
    ([], []),
    (["IIDD"], [math.nan]),          # json writes NaN either way (the runner's json_safe makes it null first)
])
def test_the_same_text_as_json_dumps_with_an_indent(keys, errors):
    s = summary(keys, errors)
    assert summary_text(s) == json.dumps(s, indent=1)


def test_nested_items_a_clashing_value_and_no_population_fall_back_to_json_dumps():
    nested = summary(["IIDD"], [[0.1, 0.2]])
    clash = summary(["IIDD"], [0.1], note="@@summary_text:final_knowledge@@")   # the mark as a value too
    plain = {"seed": 0, "runs": []}
    for s in (nested, clash, plain):
        assert summary_text(s) == json.dumps(s, indent=1)
