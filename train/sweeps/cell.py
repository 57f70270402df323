"""One cell's rows: its condition on its object set with its seed, all its orders one batched agent (as
benches/ablation.py runs them), and the resolved config the rows name (docs/sweeps.md "The rows").

A deterministic function of the cell's spec, on one torch thread: the same spec gives the same rows on any
worker, or in-process.
"""

from __future__ import annotations

import json

from train.sweeps import provenance
from train.sweeps.spec import agent_config, digest

BATCH_MAX_TRAIN = 500    # the batch answer compares every pair of a set's train objects: up to this many
RULE_LETTERS = "SEGU"        # aesop_torch.rules.RULE_NAMES, without torch (for checking rows read back)
STATE_LETTERS = "ULDI"       # aesop_torch.rules.KNOWLEDGE_LETTERS, the same
# aesop_torch.encoders.OBJECT_PROPERTIES: a model has the paper's four or the split five (null in the others)
PROPERTY_COLUMNS = ("color", "shape", "fill", "elongation", "size", "weight")


def objects_of(cell: dict, objects: dict | None):
    """The cell's ObjectSet: an objects file's data as sent, or the generated set drawn again."""
    from sim.objects import parse_objects
    if objects is None:
        from sim.make_objects import generate
        g = cell["source"]["generate"]
        objects = generate(g["seed"], g["train"], g["probe"], g["pairs"], g["jar"])
    return parse_objects(objects)


def world_outcomes(cell: dict, objects: dict | None) -> tuple[dict, dict]:
    """(outcomes, probes) as train.learning.experiment.closed_form_outcomes gives them, in the cell's world: the closed form
    with the simulated robot's noise (closed_form), without noise (closed_form_exact), or the pybullet world, each
    distinct train object dropped once and each probe inspected once (physics: the jar is reset between episodes,
    so an object's outcome does not depend on the order it comes in; train/run.py's cached physics)."""
    from train.learning.experiment import (
        closed_form_outcomes,
        outcome_record,
        plain_measurement,
    )
    objs, seed = objects_of(cell, objects), cell["seed"]
    if cell["world"] != "physics":
        from sim.sensor_model import SensorModel
        return closed_form_outcomes(objs, reachable_above_cm3=_REACH_CM3,
                                    sensor=SensorModel() if cell["world"] == "closed_form" else None, seed=seed)
    from sim.objects import archimedes_cm3
    from train.learning.sim_pool import Physics
    physics = Physics(objs, seed=seed, workers=1)   # in this process: a cell is one core's work
    try:
        jobs = [("drop", o.name, False) for o in objs.train] + [("inspect", o.name, None) for o in objs.probe]
        results = physics.run(jobs)
    finally:
        physics.close()
    outcomes = {o.name: outcome_record(r) for o, r in zip(objs.train, results)}
    probes = {o.name: {"measurement": plain_measurement(m), "archimedes_cm3": float(archimedes_cm3(o, objs.jar))}
              for o, m in zip(objs.probe, results[len(objs.train):])}
    return outcomes, probes


_REACH_CM3 = 200.0   # the closed forms' reach: the ball counts as reached after more than this (closed_form_outcomes)


def config_record(cell: dict) -> dict:
    """The configs a cell runs with, fully resolved, as JSON data: {"agent": its AgentConfig without the seed (the
    rows' seed column), "world": {"name", "sensor": the SensorModel's noise (closed_form) or null, "reachable_above_cm3"
    (the closed forms), "physics": the pybullet WorldConfig (physics)}}. The same for every cell of a condition, set
    size and world: DIR/configs.json holds each once, keyed by config_hash."""
    key = json.dumps([cell["condition"], cell["n_train"], cell["world"]], sort_keys=True)
    if key not in _CONFIGS:
        from dataclasses import asdict
        agent = agent_config(cell["condition"], 0, cell["n_train"]).to_dict()
        agent.pop("seed", None)
        world: dict = {"name": cell["world"]}
        if cell["world"] == "physics":
            from sim.world import WorldConfig
            world["physics"] = asdict(WorldConfig())
        else:
            from sim.sensor_model import SensorModel
            world["sensor"] = asdict(SensorModel()) if cell["world"] == "closed_form" else None
            world["reachable_above_cm3"] = _REACH_CM3
        _CONFIGS[key] = json.loads(json.dumps({"agent": agent, "world": world}, default=str))
    return _CONFIGS[key]


_CONFIGS: dict = {}


def config_hash(record: dict) -> str:
    """The rows' config column: the first 16 hex digits of the SHA-256 of config_record's canonical JSON."""
    return digest(record)[:16]


def world_key(cell: dict) -> str:
    """Cells with the same key see the same world (conditions differ): a physics world is simulated once per key."""
    return digest([cell["world"], cell["source"], cell["seed"]])


def schema():
    """The Parquet rows' schema (docs/sweeps.md)."""
    import pyarrow as pa
    return pa.schema([
        ("cell", pa.string()), ("condition", pa.string()), ("model", pa.string()), ("ablate", pa.string()),
        ("overrides", pa.string()), ("config", pa.string()), ("commit", pa.string()), ("world", pa.string()),
        ("set_group", pa.string()), ("set", pa.string()),
        ("generator_seed", pa.int64()), ("seed", pa.int64()), ("n_train", pa.int32()), ("n_probe", pa.int32()),
        ("n_orders", pa.int32()), ("order", pa.int32()), ("episode", pa.int32()), ("object", pa.string()),
        ("predicted_cm3", pa.float64()), ("observed_cm3", pa.float64()), ("archimedes_cm3", pa.float64()),
        ("sank", pa.bool_()), ("goal_reached", pa.bool_()), ("rules", pa.string()), ("knowledge", pa.string()),
        *[(p, pa.string()) for p in PROPERTY_COLUMNS], ("context_knowledge", pa.string()),
        ("probe_rel_error", pa.float64()),
        ("batch_knowledge", pa.string()), ("stored", pa.int32()), ("recalled", pa.float64()),
        ("probe_errors", pa.list_(pa.float64())), ("probe_floors", pa.list_(pa.float64()))])


def _median_rows(err):
    """(B, Q) errors -> (B,) median over the row (the mean of the middle two for an even count)."""
    s = err.sort(dim=1).values
    q = s.shape[1]
    return s[:, q // 2] if q % 2 else s[:, q // 2 - 1:q // 2 + 1].mean(1)


def run_cell(cell: dict, objects: dict | None = None, world: tuple | None = None, commit: str | None = None):
    """One cell: its condition on its object set with its seed, all its orders as one batched agent, as
    benches/ablation.py runs them. cell: a cell's spec (load_sweep's cells[i]["spec"]); objects: the objects file's
    data (None: a generated set, drawn here); world: (outcomes, probes) when already simulated; commit: the code's
    commit, every row's `commit` (None: this checkout's, provenance.commit). Returns the cell's
    rows (a pyarrow Table of `schema()`, order by order, episode by episode). A deterministic function of its
    arguments, on one torch thread."""
    import numpy as np
    import pyarrow as pa
    import torch

    from aesop_torch.agent import Agent
    from aesop_torch.rules import KNOWLEDGE_LETTERS
    from train.learning.experiment import draw_orders, one_thread, stack_measurements

    with one_thread(), torch.no_grad():
        objs = objects_of(cell, objects)
        outcomes, probes = world if world is not None else world_outcomes(cell, objects)
        names, pnames = [o.name for o in objs.train], [o.name for o in objs.probe]
        n = len(names)
        meas = stack_measurements([outcomes[k]["measurement"] for k in names])
        observed = torch.tensor([outcomes[k]["observed_cm3"] for k in names], dtype=torch.float64)
        ep = {k: torch.tensor([outcomes[x][k] for x in names]) for k in ("goal_before", "goal_after", "sank")}
        pmeas = stack_measurements([probes[k]["measurement"] for k in pnames]) if pnames else None
        truth = torch.tensor([probes[k]["archimedes_cm3"] for k in pnames])
        orders = torch.tensor(draw_orders(n, cell["orders"], cell["seed"]))
        B, Q = orders.shape[0], len(pnames)
        agent = Agent(agent_config(cell["condition"], cell["seed"], n), batch=B)
        checks = set(cell["checks"])
        predicted, fired, state, stored, by_context = [], [], [], [], []
        probe_err = torch.full((n, B), float("nan"), dtype=torch.float64)
        recalled = torch.full((n, B), float("nan"), dtype=torch.float64)
        per_probe = {}   # episode index -> (B, Q) each probe's error
        floors = None
        if Q:   # the senses' floor: Archimedes applied to the probes as the robot measures them (water at 1 g/cm^3)
            sensed = torch.minimum(pmeas["mass_g"], pmeas["fill"] * pmeas["extent_cm"].prod(-1))
            floors = torch.nan_to_num((sensed - truth).abs() / truth, nan=1.0).double().tolist()
        active = agent.config.explore == "active"
        if active:   # the robot chooses its next object: it looks at (and lifts) every one on the stand
            from aesop_torch.exploration import choose_in_order
            seen = agent.activities(meas)
        for t in range(n):
            obj = choose_in_order(agent, *seen, orders, t) if active else orders[:, t]
            res = agent.step({k: v[obj] for k, v in meas.items()}, observed[obj].float(), ep["goal_before"][obj],
                             ep["goal_after"][obj], sank=ep["sank"][obj])
            predicted.append(res.expected.double())
            fired.append(res.rules_fired().clone())
            state.append(agent.rules.state.clone())
            if hasattr(agent.rules, "context_state"):   # knowledge kept per context (contextual_rules.CONTEXTS)
                by_context.append(agent.rules.context_state.clone())
            stored.append(agent.memory.count.clone())
            if t + 1 in checks and Q:
                probe = agent.select(torch.arange(B).repeat_interleave(Q))
                p = probe.anticipate({k: v.repeat(B, *([1] * (v.ndim - 1))) for k, v in pmeas.items()})
                err = torch.nan_to_num((p.expected.view(B, Q) - truth).abs() / truth, nan=1.0)   # none: 100 %
                probe_err[t] = _median_rows(err).double()   # as benches/ablation.py
                per_probe[t] = err.double()
                recalled[t] = p.recall.valid.sum(1).view(B, Q).double().mean(1)   # episodes recalled per cue
        batch = None
        if n <= BATCH_MAX_TRAIN:   # the batch answer: every pair of the set's episodes compared at once
            from aesop_torch.rules import batch_knowledge
            codes = batch_knowledge(*agent.pairwise_evidence(meas, observed.float(), ep["sank"]), agent.config.rules,
                                    properties=agent.properties)
            batch = "".join(KNOWLEDGE_LETTERS[c] for c in codes.tolist())
    # rows order by order, episode by episode: (n, B) -> (B, n) -> flat
    flat = lambda x: np.ascontiguousarray(np.asarray(x).T).reshape(-1)
    obj_idx = orders.numpy()                                            # (B, n)
    pred = flat(torch.stack(predicted).numpy())
    perr = flat(probe_err.numpy())
    fired_codes = torch.stack(fired).permute(1, 0, 2).reshape(B * n, -1).tolist()
    state_codes = torch.stack(state).permute(1, 0, 2).reshape(B * n, -1).tolist()
    knowledge = ["".join(KNOWLEDGE_LETTERS[c] for c in row) for row in state_codes]
    props = list(agent.properties)
    context_knowledge = [None] * (B * n)
    if by_context:   # "floating:LETTERS;sinking:LETTERS;fate:LETTERS", one letter per property as `knowledge`
        names_c = agent.rules.contexts
        codes = torch.stack(by_context).permute(1, 0, 2, 3).reshape(B * n, len(names_c), -1).tolist()
        context_knowledge = [";".join(f"{c}:" + "".join(KNOWLEDGE_LETTERS[x] for x in row)
                                      for c, row in zip(names_c, rows)) for rows in codes]
    arch = np.array([outcomes[k]["archimedes_cm3"] for k in names])
    cond, N = cell["condition"], B * n
    col = lambda v, typ: pa.array([v] * N, typ)
    s = schema()
    data = {
        "cell": col(digest(cell)[:16], pa.string()), "condition": col(cond["name"], pa.string()),
        "model": col(cond["model"], pa.string()), "ablate": col(",".join(cond["ablate"]), pa.string()),
        "overrides": col(json.dumps(cond["overrides"], sort_keys=True), pa.string()),
        "config": col(config_hash(config_record(cell)), pa.string()),
        "commit": col(provenance.commit() if commit is None else commit, pa.string()),
        "world": col(cell["world"], pa.string()), "set_group": col(cell["set_group"], pa.string()),
        "set": col(cell["set"], pa.string()),
        "generator_seed": col(cell["source"].get("generate", {}).get("seed"), pa.int64()),
        "seed": col(cell["seed"], pa.int64()), "n_train": col(n, pa.int32()), "n_probe": col(Q, pa.int32()),
        "n_orders": col(B, pa.int32()),
        "order": pa.array(np.repeat(np.arange(B), n), pa.int32()),
        "episode": pa.array(np.tile(np.arange(1, n + 1), B), pa.int32()),
        "object": pa.array([names[i] for i in obj_idx.reshape(-1)], pa.string()),
        "predicted_cm3": pa.array(pred, pa.float64(), mask=np.isnan(pred)),
        "observed_cm3": pa.array(observed.numpy()[obj_idx].reshape(-1), pa.float64()),
        "archimedes_cm3": pa.array(arch[obj_idx].reshape(-1), pa.float64()),
        "sank": pa.array(ep["sank"].numpy()[obj_idx].reshape(-1).astype(bool), pa.bool_()),
        "goal_reached": pa.array(ep["goal_after"].numpy()[obj_idx].reshape(-1).astype(bool), pa.bool_()),
        "rules": pa.array(["".join(RULE_LETTERS[c] for c in row) for row in fired_codes], pa.string()),
        "knowledge": pa.array(knowledge, pa.string()),
        **{p: pa.array([k[props.index(p)] if p in props else None for k in knowledge], pa.string())
           for p in PROPERTY_COLUMNS},
        "context_knowledge": pa.array(context_knowledge, pa.string()),
        "probe_rel_error": pa.array(perr, pa.float64(), mask=np.isnan(perr)),
        "batch_knowledge": col(batch, pa.string()),
        "stored": pa.array(flat(torch.stack(stored).numpy()), pa.int32()),
        "recalled": pa.array(flat(recalled.numpy()), pa.float64(), mask=np.isnan(flat(recalled.numpy()))),
        "probe_errors": pa.array([per_probe[t][b].tolist() if t in per_probe else None
                                  for b in range(B) for t in range(n)], pa.list_(pa.float64())),
        "probe_floors": pa.array([floors if t in per_probe else None for b in range(B) for t in range(n)],
                                 pa.list_(pa.float64())),
    }
    return pa.table([data[f.name] for f in s], schema=s)


def cell_id(cell: dict) -> str:
    return digest(cell)[:16]


