"""A checkpoint's values within their ranges, before an Experiment is restored from them.

train.learning.checkpoint.load calls `state_problem` after its structure check (keys, types, shapes and dtypes are right),
without importing train.learning.experiment (which imports train.learning.checkpoint).
"""

from __future__ import annotations

import math


MEASUREMENT_LENGTHS = {"rgb": 3, "extent_cm": 3, "fill": None, "mass_g": None}


def finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def measurement_ok(m) -> bool:
    if not isinstance(m, dict) or set(m) != set(MEASUREMENT_LENGTHS):
        return False
    for k, length in MEASUREMENT_LENGTHS.items():
        v = m[k]
        if length is None and not finite(v):
            return False
        if length is not None and not (isinstance(v, list) and len(v) == length and all(map(finite, v))):
            return False
    return True


def state_problem(e: dict, run: dict) -> str | None:
    """What is out of range in a checkpoint's experiment (`Experiment.state_dict`) and run, or None: the run's
    objects as the objects file would take them, the names they give, each part's values (`_outcomes_problem`,
    `_records_problem`, `_agent_values_problem`). The config is checked with the structure (train.learning.checkpoint)."""
    from sim.objects import ObjectsFileError, parse_objects
    try:
        objects = parse_objects(run["objects"])
    except ObjectsFileError as err:
        return f"the run's objects: {err}"
    if [o.name for o in objects.train] != e["train_names"] or [o.name for o in objects.probe] != e["probe_names"]:
        return "the run's objects are not the experiment's train and probe objects"
    jar_cm3 = objects.jar.area_cm2 * objects.jar.height_cm
    return (_outcomes_problem(e, objects.jar) or _records_problem(e, jar_cm3) or _agent_values_problem(e))


# what the senses can give for an object the objects file admits (sim.objects.ObjectsConfig): the least fill of its
# shapes is a sphere's, pi / 6 = 0.52 (MIN_FILL: half of it, for the camera's error); sides of 1 cm up to the 29 cm
# jar (MIN_EXTENT_CM, MAX_EXTENT_CM: 10x either way); 1 kg at most, the hand's noise at most a quarter of the
# heaviest object (train/runner/config_checks.py), so MAX_MASS_G: 10x
MIN_FILL, MIN_EXTENT_CM, MAX_EXTENT_CM, MAX_MASS_G = 0.25, 0.1, 290.0, 10_000.0


def _measurement_problem(m: dict) -> str | None:
    """What the senses cannot have measured: a mean pixel colour outside 0..1, a fill (volume over bounding box)
    outside [MIN_FILL, 1], an extent or a felt mass that is not positive (the encoders take their logs) or beyond
    what an object the objects file admits could give."""
    if not all(0.0 <= x <= 1.0 for x in m["rgb"]):
        return f"rgb {m['rgb']} outside 0..1"
    if not MIN_FILL <= m["fill"] <= 1.0:
        return f"fill {m['fill']} outside [{MIN_FILL}, 1]"
    if not all(x > 0 for x in m["extent_cm"]) or not m["mass_g"] > 0:
        return f"extent_cm {m['extent_cm']} or mass_g {m['mass_g']} not positive"
    if not all(MIN_EXTENT_CM <= x <= MAX_EXTENT_CM for x in m["extent_cm"]):
        return f"extent_cm {m['extent_cm']} outside {MIN_EXTENT_CM:g} .. {MAX_EXTENT_CM:g} cm"
    if not m["mass_g"] <= MAX_MASS_G:
        return f"mass_g {m['mass_g']:g} above {MAX_MASS_G:g} g"
    return None


def _outcomes_problem(e: dict, jar) -> str | None:
    """Outcomes and probes: measurements the senses can give, and volumes no larger than the jar (a drop cannot
    raise the level by more than the jar is tall, nor an object displace more than the jar holds)."""
    jar_cm3 = jar.area_cm2 * jar.height_cm
    for kind, table in (("outcome", e["outcomes"]), ("probe", e["probes"])):
        for name, o in table.items():
            if p := _measurement_problem(o["measurement"]) or ("true" in o and _true_problem(o["true"])):
                return f"{kind} of {name!r}: {p}"
            volumes = [o["archimedes_cm3"]] + ([o["observed_cm3"]] if kind == "outcome" else [])
            if not 0.0 < o["archimedes_cm3"] <= jar_cm3 or any(abs(v) > jar_cm3 for v in volumes):
                return (f"{kind} of {name!r}: a volume of {max(map(abs, volumes)):g} cm^3, the jar holds "
                        f"{jar_cm3:.0f} cm^3")
    return None


RECORD_KEYS = {"object", "predicted_cm3", "observed_cm3", "archimedes_cm3", "rules", "knowledge", "encoded",
               "goal_reached", "probe_rel_error", "perceived"}
RECORD_OPTIONAL = {"true", "certainty_by_context"}   # the file's values, for the logs; a contextual model's certainty
TRUE_KEYS = {"extent_cm", "fill", "mass_g"}   # sim.objects.ObjectSpec.true_values
# a prediction is a weighted average of recalled rewards (paper) or a fit over them (extended): beyond 100 jars of
# water it is no reading of these objects
PREDICTION_JARS = 100.0
# a relative error beyond this is no probe's (a prediction within PREDICTION_JARS jars of a probe's >= 0.1 cm^3)
MAX_REL_ERROR = 1e9


def _records_problem(e: dict, jar_cm3: float = math.inf) -> str | None:
    """Each order's records name the objects its order dropped, in that order, and every field of a record is what
    train.learning.experiment.Experiment.step writes, of its type and in its range (summary.json, the figure and the logs
    are made from them as they are: a NaN or a string in a number's place would reach them)."""
    from aesop_torch.rules import PROPERTIES, RULE_NAMES, STATES

    names = e["train_names"]
    properties = tuple(e["config"].get("encoder", {}).get("properties", PROPERTIES))
    for b, (order, records) in enumerate(zip(e["orders"], e["records"])):
        for i, rec in enumerate(records):
            where = f"order {b + 1}'s episode {i + 1}"
            if rec.get("object") != names[order[i]] or not isinstance(rec.get("encoded"), bool):
                return f"{where} is not a record of {names[order[i]]!r}"
            if not RECORD_KEYS <= set(rec) <= RECORD_KEYS | RECORD_OPTIONAL:
                missing, extra = sorted(RECORD_KEYS - set(rec)), sorted(map(str, set(rec) - RECORD_KEYS -
                                                                            RECORD_OPTIONAL))
                return (f"{where}'s record keys: missing {', '.join(missing) or 'none'}, unexpected "
                        f"{', '.join(map(_cut, extra)) or 'none'}")
            if p := _record_problem(rec, jar_cm3, properties, RULE_NAMES, STATES):
                return f"{where}: {p}"
    return None


def _cut(text: str) -> str:
    """A string from the file as a message quotes it: escaped (no control character reaches a terminal), cut."""
    shown = repr(text)
    return shown if len(shown) <= 40 else shown[:37] + "..."


def _record_problem(rec: dict, jar_cm3: float, properties, rule_names, states) -> str | None:
    for k in ("observed_cm3", "archimedes_cm3"):
        if not finite(rec[k]) or abs(rec[k]) > jar_cm3:
            return f"{k} {_cut(str(rec[k]))} is not a volume the jar holds ({jar_cm3:.0f} cm^3)"
    v = rec["predicted_cm3"]
    if v is not None and (not finite(v) or abs(v) > PREDICTION_JARS * jar_cm3):
        return f"predicted_cm3 {_cut(str(v))} is not a prediction (a finite volume within {PREDICTION_JARS:g} jars)"
    v = rec["probe_rel_error"]
    if v is not None and (not finite(v) or not 0 <= v <= MAX_REL_ERROR):
        return f"probe_rel_error {_cut(str(v))} is not a relative error"
    if not isinstance(rec["goal_reached"], bool):
        return f"goal_reached {_cut(str(rec['goal_reached']))} is not true or false"
    knowledge, rules = rec["knowledge"], rec["rules"]
    if not isinstance(knowledge, dict) or not isinstance(rules, dict) or not set(properties) <= set(knowledge) \
            or set(rules) != set(knowledge):
        return f"knowledge and rules must name the same properties, among them {', '.join(properties)}"
    for prop, k in knowledge.items():
        if not isinstance(k, dict) or set(k) != {"state", "certainty"} or k["state"] not in states \
                or not finite(k["certainty"]) or not 0 <= k["certainty"] <= 1:
            return f"knowledge of {_cut(str(prop))} is not a state of {', '.join(states)} with a certainty in 0..1"
        if rules[prop] not in rule_names:
            return f"rules of {_cut(str(prop))}: {_cut(str(rules[prop]))} is not one of {', '.join(rule_names)}"
    m = rec["perceived"]
    if not measurement_ok(m) or (p := _measurement_problem(m)):
        return f"perceived: {p if measurement_ok(m) else 'not a measurement (rgb, extent_cm, fill, mass_g)'}"
    if "true" in rec and (p := _true_problem(rec["true"])):
        return p
    by = rec.get("certainty_by_context", {})
    if not isinstance(by, dict) or not all(
            isinstance(c, dict) and set(c) == set(properties) and all(finite(x) and 0 <= x <= 1 for x in c.values())
            for c in by.values()) or not set(by) <= {"floating", "sinking", "fate"}:
        return "certainty_by_context is not a certainty in 0..1 per context (floating, sinking, fate) and property"
    return None


def _true_problem(true) -> str | None:
    if not (isinstance(true, dict) and set(true) <= TRUE_KEYS and all(
            finite(x) or (isinstance(x, list) and len(x) == 3 and all(map(finite, x))) for x in true.values())):
        return f"true is not the file's values ({', '.join(sorted(TRUE_KEYS))}: numbers)"
    return None




def _agent_values_problem(e: dict) -> str | None:
    """The agents' values within the bounds their learning keeps them in, and their counts within the t episodes
    the records hold (a rolled-back t leaves episodes the records do not account for).
    - maps' codebooks in 0..1: every map's input lies in 0..1 (rgb; fill and the extent ratios, sorted descending;
      size and mass on the log unit of their range, where the developmental samples are drawn; unit-length
      non-negative word vectors) and a SOM unit starts at a sample and only moves to weighted means of samples;
    - maps' locations: the grid the map's config gives (rebuilt, never learned);
    - pathway strengths in [0, max(1, rules.dominant_strength)]: they start at 1, Growth raises them up to the
      dominant strength, Elimination and Uncertainty only lower them;
    - the hub's branches in 0..1 (map activities) and their energies (sums of squares) at most the units;
    - episodes stored (memory.count) at most the records' encoded episodes; assemblies at most t; a neuron's usage at
      most the assemblies; rules fired once per property and episode, Uncertainty counted once per comparison (at most
      t * t); states codes of rules.STATES."""
    import torch

    from aesop_torch.encoders import default_map_configs
    from aesop_torch.rules import STATES
    from aesop_torch.som import SelfOrganizingMap

    a, t, cfg = e["agent"], e["t"], e["config"]
    top = max(1.0, float(cfg["rules"]["dominant_strength"]))
    encoded = torch.tensor([sum(r["encoded"] for r in rec) for rec in e["records"]])
    n_assemblies = a["hub.n_assemblies"]

    def within(key, lo, hi) -> str | None:
        v = a[key]
        if v.numel() and not (bool((v >= lo).all()) and bool((v <= hi).all())):
            return (f"agent state {key!r} holds values outside [{lo:g}, {hi:g}] "
                    f"({float(v.min()):g} .. {float(v.max()):g})")
        return None

    from aesop_torch.encoders import EncoderConfig
    for name, map_config in default_map_configs(EncoderConfig(**cfg["encoder"])).items():
        if p := within(f"maps.{name}.weights", 0.0, 1.0):
            return p
        if not torch.equal(a[f"maps.{name}.locations"], SelfOrganizingMap(map_config).locations):
            return f"agent state 'maps.{name}.locations' is not the map's grid"
    checks = [("hub.strength", 0.0, top), ("hub.branches", 0.0, 1.0),
              ("hub.branch_norm", 0.0, float(a["hub.branches"].shape[-1])), ("memory.count", 0, t),
              ("hub.n_assemblies", 0, t), ("hub.usage", 0, t), ("rules.state", 0, len(STATES) - 1)]
    # the rules fire once per property and episode (paper), or once per comparison, with each recalled episode, in
    # each context (contextual: fired (B, contexts, P, 4), up to t * t)
    per_comparison = "rules.fired" in a and a["rules.fired"].dim() == 4
    fired_max = t * t if per_comparison else t
    if "rules.strength" in a:   # the paper and contextual models' rules
        checks += [("rules.strength", 0.0, top), ("rules.fired", 0, fired_max)]
    if "rules.uncertain_count" in a:   # the extended model's: once per comparison, an episode against each recalled
        checks += [("rules.uncertain_count", 0, t * t)]   # one (at most t of them), so up to t * t
    for key, lo, hi in checks:
        if p := within(key, lo, hi):
            return p
    if (a["memory.count"] > encoded).any():
        return (f"the agents hold {a['memory.count'].tolist()} episodes, their records encoded "
                f"{encoded.tolist()} (t = {t})")
    if (a["hub.usage"] > n_assemblies[:, None]).any():
        return "a hub neuron is used by more assemblies than the hub holds"
    if "rules.fired" in a and (a["rules.fired"].sum(-1) > fired_max).any():
        return f"the rules fired more than {'t * t' if per_comparison else 'once'} per property in {t} episode(s)"
    return None
