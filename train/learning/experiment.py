"""Cumulative learning over episodes: B agents, one per presentation order, learning side by side.

The physics is a source of measurements and outcomes. With the jar reset between episodes an object's outcome does
not depend on the order it came in, so by default (`physics="cached"`) each distinct object is simulated once and its
measured outcome reused by every agent; `physics="per-episode"` runs the full simulation for every episode of every
agent. Either way the agent only ever sees what the world measured.
"""

from __future__ import annotations

import contextlib
import math
import statistics
from dataclasses import InitVar, dataclass, field

import numpy as np
import torch

from aesop_torch.agent import Agent, AgentConfig
from aesop_torch.rules import RULE_NAMES
from train.learning import checkpoint
from sim.errors import WorldBuildError

MEASUREMENT_KEYS = ("rgb", "extent_cm", "fill", "mass_g")


def stack_measurements(ms: list[dict]) -> dict:
    """A list of per-object measurement dicts -> one batched dict of float32 tensors."""
    return {k: torch.tensor([list(m[k]) if hasattr(m[k], "__len__") else m[k] for m in ms], dtype=torch.float32)
            for k in MEASUREMENT_KEYS}


def plain_measurement(m: dict) -> dict:
    """A world measurement as plain floats and lists (it goes into checkpoints and JSON)."""
    return {k: [float(v) for v in m[k]] if hasattr(m[k], "__len__") else float(m[k]) for k in MEASUREMENT_KEYS}


def outcome_record(outcome) -> dict:
    """The part of a world EpisodeOutcome the experiment keeps (plain numbers: it goes into checkpoints). An outcome
    that is not a measurement of the object's drop is never kept (`check_outcome`)."""
    check_outcome(outcome)
    return {
        "measurement": plain_measurement(outcome.measurement),
        "observed_cm3": float(outcome.observed_cm3),
        "archimedes_cm3": float(outcome.archimedes_cm3),
        "goal_before": bool(outcome.goal_reachable_before),
        "goal_after": bool(outcome.goal_reached_after),
        "sank": bool(outcome.sank),
        "true": dict(outcome.true),   # the file's extent, fill and mass, for the logs: never given to the agent
    }


class BadOutcome(WorldBuildError):
    """A drop's outcome that must not be recorded (check_outcome); the runner ends on it as on a world its workers
    could not build: one line, exit 1, the last checkpoint kept."""


def check_outcome(outcome) -> None:
    """Raise BadOutcome (a train.learning.sim_pool.WorldBuildError: the run ends in one line, exit 1, its last checkpoint kept)
    for a drop whose outcome would teach the agent something the world did not do: the object not delivered into
    the jar (the rise read is not its), a measurement that is not finite, or a negative displaced volume (no object
    lowers the water: the level's noise drowned the rise)."""
    name = getattr(outcome, "name", None) or "the object"
    name = f"object {name!r}" if name != "the object" else name
    if getattr(outcome, "delivered", True) is False:
        raise BadOutcome(f"{name} was not delivered into the jar (the arm did not get it there: world.move_timeout_s, "
                         "world.robot.max_velocity or the reach); its episode is not recorded")
    values = [outcome.observed_cm3, outcome.archimedes_cm3] + [
        x for v in outcome.measurement.values() for x in (v if hasattr(v, "__len__") else [v])]
    if not all(isinstance(x, (int, float)) and math.isfinite(x) for x in map(_number, values)):
        raise BadOutcome(f"{name}'s drop measured a non-finite value (displaced {outcome.observed_cm3!r} cm^3, "
                         f"measurement {plain_measurement(outcome.measurement)}); its episode is not recorded")
    if outcome.observed_cm3 < 0:
        raise BadOutcome(f"{name}'s drop read a negative displaced volume ({float(outcome.observed_cm3):.1f} cm^3: "
                         "the level's noise swamped its rise, world.level_noise_cm); its episode is not recorded")


def _number(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def closed_form_outcomes(objects, reachable_above_cm3: float = 200.0, sensor=None, seed: int = 0
                         ) -> tuple[dict, dict]:
    """(outcomes, probes) as `Experiment.outcomes` / `.probes` hold them, without physics. For tests, benchmarks and
    agents run without the simulator. sensor=None: every object displaces exactly its Archimedes volume and is
    measured exactly as the file describes it (its fate the engine's: denser than water). With a
    `sim.sensor_model.SensorModel`, measurements and outcomes carry that model's noise, drawn per object from (seed,
    name) as the world draws a drop's sensor noise, and the fate is the one the robot sees (SensorModel.sees_sinking,
    measured on the physics path: an object barely denser than water is seen floating). The ball
    counts as reached after more than reachable_above_cm3, a stand-in for the reach check (in the default jar it
    lies between 14 and 365 cm^3)."""
    from sim.objects import archimedes_cm3

    def sensed(s):
        if sensor is None:
            return s.exact_measurement(), float(archimedes_cm3(s, objects.jar))
        rng = sensor.rng(seed, s.name)
        return sensor.measure(s, rng), sensor.observe(s, objects.jar, rng)

    outcomes, probes = {}, {}
    for s in objects.train:
        m, v = sensed(s)
        outcomes[s.name] = {"measurement": m, "observed_cm3": v,
                            "archimedes_cm3": float(archimedes_cm3(s, objects.jar)),
                            "goal_before": False, "goal_after": v > reachable_above_cm3,
                            "sank": sensor.sees_sinking(s) if sensor is not None else bool(s.sinks),
                            "true": s.true_values()}
    for s in objects.probe:
        probes[s.name] = {"measurement": sensed(s)[0], "archimedes_cm3": float(archimedes_cm3(s, objects.jar))}
    return outcomes, probes


def draw_orders(n_objects: int, orders: str, seed: int, limit: int | None = None) -> list[list[int]]:
    """'listed' -> the file's order; 'all' -> every permutation; 'N' -> N random orders from the seed. limit: the
    first `limit` of them only, the same as the full draw's first (the runner's detailed orders: 64 of 9! are not
    worth drawing all 362,880)."""
    import itertools
    if orders == "listed":
        return [list(range(n_objects))]
    if orders == "all":
        return [list(p) for p in itertools.islice(itertools.permutations(range(n_objects)), limit)]
    g = torch.Generator().manual_seed(seed)
    count = int(orders) if limit is None else min(int(orders), limit)
    return [torch.randperm(n_objects, generator=g).tolist() for _ in range(count)]


def order_tensor(n_objects: int, orders: str, seed: int) -> torch.Tensor:
    """draw_orders(n_objects, orders, seed) as an (N, n_objects) long tensor, the same rows in the same order. 'all'
    is built in arrays (9! = 362,880 rows: 0.04 s against 1.0 s for the lists and their conversion)."""
    if orders != "all" or n_objects == 0:
        drawn = draw_orders(n_objects, orders, seed)
        return torch.tensor(drawn, dtype=torch.long).reshape(len(drawn), n_objects)
    rows = np.zeros((1, 0), dtype=np.int64)    # the permutations of 0..k-1 in lexicographic order, k = 0, 1, ...
    for k in range(1, n_objects + 1):
        # itertools.permutations' order: first element i = 0..k-1, then the others' permutations in their order
        rows = np.concatenate([np.concatenate([np.full((len(rows), 1), i, dtype=np.int64),
                                               np.delete(np.arange(k), i)[rows]], axis=1) for i in range(k)])
    return torch.from_numpy(rows)


def median_rel_error(predicted: torch.Tensor, truth: torch.Tensor) -> float | None:
    """Median over probes of |predicted - truth| / truth; None while no probe can be predicted. A probe the agent
    cannot predict yet (nothing recalled) counts as a 100 % error: expecting nothing is as wrong as expecting 0 cm^3."""
    if len(truth) == 0 or torch.isnan(predicted).all():
        return None
    err = torch.nan_to_num((predicted - truth).abs() / truth, nan=1.0)
    return float(statistics.median(err.tolist()))


def senses_floor(probes: dict) -> float | None:
    """The error the robot's senses leave (Figure 2's floor): median over `Experiment.probes` of
    |sensed - Archimedes| / Archimedes, sensed = min(mass_g, fill * extent volume), the best reading of Archimedes a
    measurement allows (water 1 g/cm^3: a floater displaces its mass, a sinker its volume). None without probes."""
    errs = []
    for probe in probes.values():
        m = probe["measurement"]
        ext = [float(e) for e in m["extent_cm"]]
        sensed = min(float(m["mass_g"]), float(m["fill"]) * ext[0] * ext[1] * ext[2])
        errs.append(abs(sensed - probe["archimedes_cm3"]) / probe["archimedes_cm3"])
    return float(statistics.median(errs)) if errs else None


def _rounded(m: dict) -> dict:
    """A plain measurement to 3 decimals (rgb, fill) and 0.01 (cm, g): what a reader compares."""
    r = lambda v, d: [round(x, d) for x in v] if isinstance(v, list) else round(v, d)
    return {"rgb": r(m["rgb"], 3), "extent_cm": r(m["extent_cm"], 2), "fill": r(m["fill"], 3),
            "mass_g": r(m["mass_g"], 2)}


def _num(x: float) -> float | None:
    return None if (x is None or math.isnan(x)) else round(float(x), 2)


@dataclass
class Experiment:
    """All state of a run: checkpointing it (see `state_dict`) is enough to resume it exactly."""
    train_names: list[str]
    probe_names: list[str]
    orders: list[list[int]]
    seed: int = 0
    physics: str = "cached"
    config: AgentConfig = field(default_factory=AgentConfig)
    t: int = 0                                      # episodes done in every order
    records: list[list[dict]] = field(default_factory=list)
    outcomes: dict = field(default_factory=dict)    # object name -> outcome_record (cached physics)
    probes: dict = field(default_factory=dict)      # probe name -> {"measurement", "archimedes_cm3"}
    # per order, the goal trials' records (train/learning/goal_trials.py), played after the exploration; not checkpointed: they
    # are a function of the final state
    trials: list = field(default_factory=list)
    # False: the agents' maps are not trained here because a state dict is about to bring them (from_state_dict)
    develop: InitVar[bool] = True

    def __post_init__(self, develop: bool = True):
        self.config.seed = self.seed
        # an agent encodes at most one episode (and one object) per train object: size the buffers to that, so a
        # population of 40,320 agents fits in memory
        self.config.memory.max_episodes = min(self.config.memory.max_episodes, len(self.train_names))
        self.config.hub.max_assemblies = min(self.config.hub.max_assemblies, len(self.train_names))
        self.agent = Agent(self.config, batch=len(self.orders), develop=develop)
        if not self.records:
            self.records = [[] for _ in self.orders]

    @property
    def n_episodes(self) -> int:
        return len(self.train_names)

    @property
    def done(self) -> bool:
        return self.t >= self.n_episodes

    def step(self, world_episode) -> list[dict]:
        """Run episode t in every order. world_episode(name, order_index, t) -> outcome_record. With
        AgentConfig.explore "active" each order's agent chooses its object among those its order has not yet
        presented (aesop_torch/exploration.py), looking at each as its cached outcome measured it, and the order is
        rewritten from t to what was chosen (it is checkpointed: a resumed run goes on from it)."""
        if self.config.explore == "active":
            self._choose()
        names = [self.train_names[o[self.t]] for o in self.orders]
        outs = [world_episode(n, b, self.t) for b, n in enumerate(names)]
        meas = stack_measurements([o["measurement"] for o in outs])
        meas["words"] = names          # the teacher names each object as it is presented (bound in the hub)
        observed = torch.tensor([o["observed_cm3"] for o in outs])
        before = torch.tensor([o["goal_before"] for o in outs])
        after = torch.tensor([o["goal_after"] for o in outs])
        sank = torch.tensor([o["sank"] for o in outs]) if all("sank" in o for o in outs) else None
        res = self.agent.step(meas, observed, before, after, sank=sank)
        fired = res.rules_fired()
        probe_err = self.probe_errors()
        new = []
        for b, (name, out) in enumerate(zip(names, outs)):
            rec = {
                "object": name,
                "predicted_cm3": _num(float(res.expected[b])),
                "observed_cm3": round(out["observed_cm3"], 2),
                "archimedes_cm3": round(out["archimedes_cm3"], 2),
                "rules": {p: RULE_NAMES[int(fired[b, i])] for i, p in enumerate(self.agent.config.encoder.properties)},
                "knowledge": self.agent.knowledge(b),
                **self._by_context(b),
                "encoded": bool(res.encoded[b]),
                "goal_reached": out["goal_after"],
                "probe_rel_error": None if probe_err[b] is None else round(probe_err[b], 4),
                "perceived": _rounded(plain_measurement(out["measurement"])),
            }
            if "true" in out:
                rec["true"] = out["true"]
            self.records[b].append(rec)
            new.append(rec)
        self.t += 1
        return new

    def _choose(self) -> None:
        """Each order's agent chooses its object for episode t (exploration.choose_in_order), from the objects as
        their cached outcomes measured them (cached physics: every train object was dropped once up front)."""
        from aesop_torch.exploration import choose_in_order
        missing = [n for n in self.train_names if n not in self.outcomes]
        if missing:
            raise ValueError(f"explore 'active' looks at every object on the stand, but {missing[0]!r} has no "
                             "measured outcome (it needs cached physics: each object measured once up front)")
        seen = self.agent.activities(stack_measurements([self.outcomes[n]["measurement"] for n in self.train_names]))
        orders = torch.tensor(self.orders, dtype=torch.long)
        choose_in_order(self.agent, *seen, orders, self.t)
        self.orders = orders.tolist()

    def predict(self, measurement: dict) -> torch.Tensor:
        """(B,) what each order's agent expects one object to displace, in cm^3. The object: what the robot
        perceives ({rgb, extent_cm, fill, mass_g}), or an object as the objects file gives it ({shape, color,
        dims_cm, mass_g}; ValueError in one line when the file would refuse it), perceived exactly."""
        if "dims_cm" in measurement:
            from sim.objects import parse_object
            measurement = parse_object(measurement).exact_measurement()
        with one_thread():   # a few small agents: a second thread only waits on a busy core (10 ms quiet, 600 busy)
            return self.agent.predict(stack_measurements([measurement] * len(self.orders)))

    def probe_predictions(self) -> torch.Tensor:
        """(B, n_probes) expected cm^3 for every probe object, learning frozen, as `predict` gives them probe by
        probe: each probe is perceived as there (the last bits of a perception depend on its batch), then every
        (order, probe) is recalled and read out in one call on copies of the agents (recall and readout do not
        depend on the batch; 5 calls of 4 cost ~5x one of 20)."""
        B, n = len(self.orders), len(self.probe_names)
        if n == 0:
            return torch.zeros(B, 0)
        with one_thread():   # small agents' tiny ops: a second thread only waits on a busy core (see one_thread)
            seen = [self.agent.activities(stack_measurements([self.probes[name]["measurement"]] * B))
                    for name in self.probe_names]
            acts, present = (torch.stack([s[i] for s in seen], 1).flatten(0, 1) for i in (0, 1))   # order-major
            agents = self.agent.select(torch.arange(B).repeat_interleave(n))
            return agents.anticipate_acts(acts, present, decoded=False).expected.view(B, n)

    def probe_errors(self) -> list[float | None]:
        pred = self.probe_predictions()
        truth = torch.tensor([self.probes[n]["archimedes_cm3"] for n in self.probe_names])
        return [median_rel_error(pred[b], truth) for b in range(len(self.orders))]

    def _by_context(self, b: int) -> dict:
        """{"certainty_by_context": {context: {property: certainty}}} for rules that keep knowledge per context of
        their own (the contextual model's floating, sinking and fate), else nothing."""
        rules = self.agent.rules
        if not hasattr(rules, "context_certainty"):
            return {}
        cert = rules.context_certainty[b]
        props = self.agent.config.encoder.properties
        return {"certainty_by_context": {c: {p: round(float(cert[k, i]), 4) for i, p in enumerate(props)}
                                         for k, c in enumerate(rules.contexts)}}

    def final_knowledge(self) -> list[dict]:
        return [self.agent.knowledge(b) for b in range(len(self.orders))]

    def knowledge_as_it_is(self) -> list[dict]:
        """Per order, what the knowledge rests on: {"by_context": rules.by_context (dominant and irrelevant among
        floaters, sinkers, and one of each; the paper model has no contexts, its three lists are the same),
        "confounded": the dominant properties never shown alone (rules.confounded)}."""
        rules = self.agent.rules
        return [{"by_context": rules.by_context(b),
                 "confounded": [p for i, p in enumerate(self.agent.config.encoder.properties)
                                if rules.confounded[b, i]]}
                for b in range(len(self.orders))]

    def imagine(self, words: str) -> dict:
        """What each order's agent retro-activates for `words` with no object in view (Agent.imagine), as plain
        values: {"words", "orders": [per order: known, score, runner_up, and when known the colour (rgb, nearest
        named colour), shape (fill, extent ratios, nearest kind), size (cm), weight (g), each with its most active
        map unit (index, activity), expected_cm3], "expected_cm3": the median over the orders that know the words,
        or None}. ValueError (one line) for a word the agents do not know."""
        im = self.agent.imagine(words)
        orders = [_imagined(self.agent, im, b) for b in range(self.agent.batch)]
        known = [o["expected_cm3"] for o in orders if o["known"] and o["expected_cm3"] is not None]
        return {"words": words, "orders": orders,
                "expected_cm3": round(statistics.median(known), 2) if known else None}

    # -- checkpointing ----------------------------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {
            "train_names": self.train_names, "probe_names": self.probe_names, "orders": self.orders,
            "seed": self.seed, "physics": self.physics, "config": self.config.to_dict(), "t": self.t,
            "records": self.records, "outcomes": self.outcomes, "probes": self.probes,
            "agent": self.agent.state_dict(),
        }

    @classmethod
    def from_state_dict(cls, state: dict) -> "Experiment":
        exp = cls(state["train_names"], state["probe_names"], state["orders"], state["seed"], state["physics"],
                  AgentConfig.from_dict(state["config"]), state["t"], state["records"], state["outcomes"],
                  state["probes"], develop=False)
        exp.agent.load_state_dict(state["agent"])   # brings the maps' codebooks (and refreshes the lateral spread)
        return exp


@contextlib.contextmanager
def one_thread():
    """torch on one thread inside, the caller's thread count restored after. For the library's calls on a few
    agents (load_experiment, Experiment.predict, probe_predictions): hundreds of tiny ops, on which a second thread
    only waits for a busy core (measured on 2 cores, 4 agents: predict 10 ms quiet, 600 ms on two threads beside
    another job; load 0.8 ms on one thread, 12-150 ms on two)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def load_experiment(path) -> Experiment:
    """A run's checkpoint (train/run.py writes DIR/checkpoints/latest.pt), verified (train.learning.checkpoint.load), as a live
    Experiment, agents included."""
    with one_thread():   # building a few agents is hundreds of tiny ops: a second thread only waits (see one_thread)
        return Experiment.from_state_dict(checkpoint.load(path)["experiment"])


def _imagined(exp_agent, im, b: int) -> dict:
    """Agent b's Imagination as plain values: per property the decoded value and the map unit most active."""
    from aesop_torch.encoders import SHAPE_FILL
    from sim.objects import PALETTE
    e = exp_agent.config.encoder
    unit = lambda p: (int(im.acts[b, list(exp_agent.maps).index(p)].argmax()),
                      round(float(im.acts[b, list(exp_agent.maps).index(p)].max()), 3))
    v = {p: im.values[p][b].tolist() for p in im.values}
    rgb = v["color"]
    colour = min(PALETTE, key=lambda n: sum((x - y) ** 2 for x, y in zip(PALETTE[n], rgb)))
    fill, r1, r2 = v["shape"] if "shape" in v else v["fill"] + v["elongation"]   # the paper's shape, or split
    kinds = {"cube": (1.0, 1.0, 1.0), "box": (1.0, r1, r2), "cylinder": (SHAPE_FILL["cylinder"], r1, r2),
             "sphere": (SHAPE_FILL["sphere"], 1.0, 1.0)}
    kind = min(kinds, key=lambda k: sum((x - y) ** 2 for x, y in zip(kinds[k], (fill, r1, r2)))
               + (0.05 if k == "box" else 0.0))   # a box only when its sides clearly differ from a cube's
    out = {"known": bool(im.known[b]), "score": round(float(im.score[b]), 3),
           "runner_up": round(float(im.runner_up[b]), 3)}
    if not out["known"]:
        return out
    size = math.exp(v["size"][0] * math.log(e.size_max_cm / e.size_min_cm) + math.log(e.size_min_cm))
    mass = math.exp(v["weight"][0] * math.log(e.mass_max_g / e.mass_min_g) + math.log(e.mass_min_g))
    exp = float(im.anticipation.expected[b])
    return {**out,
            "color": {"rgb": [round(x, 3) for x in rgb], "nearest": colour, "unit": unit("color")},
            "shape": {"fill": round(fill, 3), "ratios": [round(r1, 3), round(r2, 3)], "kind": kind,
                      "unit": unit("shape" if "shape" in v else "fill")},
            "size": {"cm": round(size, 2), "unit": unit("size")},
            "weight": {"g": round(mass, 1), "unit": unit("weight")},
            "expected_cm3": None if math.isnan(exp) else round(exp, 2)}

