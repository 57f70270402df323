"""The Aesop battery scored as the animal studies score it: per task, agents choose among (tube, object) options over
20 trials, learning from each outcome; choices on trial 1, trials 1-5 and 1-20 against chance with an exact
one-sided binomial test (p < 0.05 = pass; chance = 1 / number of options).

The agent perceives the apparatus as it perceives an object: each option's tube enters the measurement as context
properties (EncoderConfig.context, each a SOM map of its own), so its episodes hold the substrate's look, the
tube's width, its level and its place, recall is cued by them as by the object's own properties, and the same four
rules judge them by the same comparisons (AgentConfig.properties), their pathway strengths gating recall as the
object's do. Nothing here tells the agent which option works: it predicts each option's outcome by recall, chooses
the largest, acts (the closed form `sim.apparatus.outcome` is the world), observes the rise of the reward tube and
learns (Agent.step).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, replace

import torch

from aesop_torch.agent import Agent
from aesop_torch.agent_config import AgentConfig
from aesop_torch.encoders import EncoderConfig, train_property_maps
from aesop_torch.hub import ObjectHub

# the apparatus as the agent perceives it, each a value in 0..1 on a map of its own
CONTEXT = ("surface", "width", "level", "place")
# the look of a tube's contents (how bright and grainy it is): a perceived value, not what it does
SURFACE_LOOK = {"water": 0.15, "sand": 0.6, "sawdust": 0.85}
WIDTH_RANGE_CM = (1.0, 30.0)      # as the size map's range: tubes from a finger's width to a bucket's
REWARD_SCALE = 10.0               # the reward tube's rise in mm as the reward the memory stores (its code is log-scaled
                                  # from 0.5, so a rise of 0.05 cm is the smallest that registers)
TRIALS = 20
AIMS = ("gap", "rise")   # what a choice aims at (play's aim)


def binomial_tail(k: int, n: int, p: float) -> float:
    """P(X >= k) for X ~ Binomial(n, p): the one-sided exact test of k correct choices out of n at chance p."""
    if not 0 <= k <= n or not 0 < p < 1:
        raise ValueError(f"binomial_tail needs 0 <= k <= n and 0 < p < 1, got k={k}, n={n}, p={p}")
    return sum(math.comb(n, i) * p ** i * (1 - p) ** (n - i) for i in range(k, n + 1))


@dataclass(frozen=True)
class Score:
    correct: int
    n: int
    chance: float

    @property
    def p(self) -> float:
        return binomial_tail(self.correct, self.n, self.chance)

    @property
    def passed(self) -> bool:
        return self.p < 0.05

    @property
    def percent(self) -> float:
        return 100.0 * self.correct / self.n


def score(correct: list[list[bool]], chance: float) -> dict:
    """Per-agent trial-by-trial correctness -> {"trial 1", "1-5", "1-20"}: pooled Scores over agents (as the studies
    pool a subject's trials; here every agent is a subject)."""
    out = {}
    for label, upto in (("trial 1", 1), ("1-5", 5), ("1-20", TRIALS)):
        out[label] = Score(sum(sum(c[:upto]) for c in correct), sum(len(c[:upto]) for c in correct), chance)
    return out


_MAPS: dict = {}


def context_agent(config: AgentConfig, batch: int) -> Agent:
    """An agent whose maps include the context maps of config.encoder.context (their hub branches too), and whose
    rules judge them with the object's properties (AgentConfig.properties). The maps are developed as the Agent
    develops them (from config.encoder, same seed: the property maps are bit-identical, the context maps' draws come
    after theirs), once per seed, and shared between agents of the same seed: maps never change after development."""
    if not config.encoder.context:
        return Agent(config, batch=batch)
    agent = Agent(config, batch=batch, develop=False)
    key = (config.seed, config.som_samples, config.som_epochs, repr(config.encoder))
    if key not in _MAPS:
        g = torch.Generator().manual_seed(config.seed)
        _MAPS[key] = train_property_maps(config.som_samples, g, epochs=config.som_epochs, config=config.encoder)
    agent.maps = _MAPS[key]
    agent.hub = ObjectHub({name: m.weights.shape[0] for name, m in agent.maps.items()}, config.hub, batch=batch)
    return agent


def make_config(model: str, ablate: tuple = (), seed: int = 0, extra: int = 64) -> AgentConfig:
    c = AgentConfig()
    c = replace(c, model=model, ablate=tuple(ablate), seed=seed, encoder=replace(c.encoder, context=CONTEXT))
    c.memory.max_episodes += extra
    c.hub.max_assemblies += extra
    return c


def stack(ms: list[dict]) -> dict:
    """Per-agent measurements (plain, with a "context" dict) -> one batched measurement."""
    out = {k: torch.tensor([list(m[k]) if hasattr(m[k], "__len__") else m[k] for m in ms], dtype=torch.float32)
           for k in ("rgb", "extent_cm", "fill", "mass_g")}
    out["context"] = {k: torch.tensor([m["context"][k] for m in ms], dtype=torch.float32) for k in ms[0]["context"]}
    return out


def play(agent: Agent, options: list[dict], world, correct: set, explore: list[list[int]], trials: int = TRIALS,
         seed: int = 0, offered: int | None = None, aim: str = "gap") -> tuple[list[list[bool]], list[list[int]]]:
    """The agent's B agents explore, then play `trials` trials, learning all the while.

    options: per option its measurement (an object's, with "context"). world(i) -> (rise_cm, reached) of option i
    from the trial's starting state. correct: the options that count as correct. explore: per agent the options it
    tries first, in order (the same length for all). offered: the first `offered` options are the trials'
    choices (default all; the rest are exploration's only). aim: "gap" (default) chooses the option whose predicted
    rise leaves its reward the least short of reach (an option's "gap_cm": how far below reach the reward it raises
    is seen, as the runner's goal trials aim at the ball's gap); "rise" the largest predicted rise, the gap unseen.
    With equal gaps the two choose alike. Returns (per agent per trial correct, per agent choices)."""
    if aim not in AIMS:
        raise ValueError(f"aim must be one of {AIMS}, got {aim!r}")
    B = agent.batch
    rng = random.Random(seed)
    offered = len(options) if offered is None else offered

    def act(chosen: list[int]) -> None:
        outs = [world(i) for i in chosen]
        observed = torch.tensor([max(REWARD_SCALE * r, 0.0) for r, _ in outs])
        reached = torch.tensor([bool(x) for _, x in outs])
        agent.step(stack([options[i] for i in chosen]), observed, torch.zeros(B, dtype=torch.bool), reached)

    for step in range(len(explore[0]) if explore else 0):
        act([explore[b][step] for b in range(B)])
    right = [[] for _ in range(B)]
    chosen_all = [[] for _ in range(B)]
    gaps = [options[i].get("gap_cm", 0.0) if aim == "gap" else 0.0 for i in range(offered)]
    # the predicted margin over the closest gap, in the stored reward's unit: exactly the predicted rise when the
    # gaps are equal (no rounding), so only a difference in what is seen of the rewards changes the choice
    shortfall = torch.tensor([REWARD_SCALE * (g - min(gaps)) if g != min(gaps) else 0.0 for g in gaps])
    for _ in range(trials):
        expected = torch.stack([agent.predict(stack([options[i]] * B)) for i in range(offered)], 1)   # (B, offered)
        expected = expected - shortfall
        chosen = []
        for b in range(B):
            e = expected[b].tolist()
            known = [i for i, x in enumerate(e) if not math.isnan(x)]
            best = max((e[i] for i in known), default=None)
            ties = [i for i in known if e[i] == best] or list(range(offered))
            chosen.append(rng.choice(ties))
        for b, i in enumerate(chosen):
            right[b].append(i in correct)
            chosen_all[b].append(i)
        act(chosen)
    return right, chosen_all


# -- the apparatus tasks (sim/apparatus.py) ------------------------------------------------------------------------
def reward_gap_cm(task, tube, levels: dict) -> float:
    """How far below reach the reward an option raises is seen: the dropped-into tube's own reward, or else the
    apparatus' reward closest to reach (which tube a hidden channel joins is not seen)."""
    rewards = [tube] if tube.reward else [t for t in task.tubes if t.reward]
    return min(t.height_cm - task.reach_cm - levels[t.name] for t in rewards)


def perceived(task, tube, obj) -> dict:
    """A (tube, object) option as the agent perceives it: the object's measurement, the tube's context and the gap
    of the reward it raises (reward_gap_cm, for the choice)."""
    m = dict(obj.exact_measurement())
    m["gap_cm"] = reward_gap_cm(task, tube, task.start_levels())
    names = [t.name for t in task.tubes]
    lo, hi = WIDTH_RANGE_CM
    d = min(max(tube.inner_diameter_cm, lo), hi)
    m["context"] = {"surface": SURFACE_LOOK[tube.substrate],
                    "width": (math.log(d) - math.log(lo)) / (math.log(hi) - math.log(lo)),
                    "level": min(max(tube.level_cm / tube.height_cm, 0.0), 1.0),
                    "place": names.index(tube.name) / max(len(names) - 1, 1)}
    return m


def task_world(task, outcome=None, perceive=None):
    """(options, world(i), correct) of a task: every option from the task's starting levels (each trial is set up
    afresh, as in the studies), correct = the options that bring the reward in reach (else those that raise it most)."""
    if outcome is None:
        from sim.apparatus import outcome
    opts = list(task.options())
    levels = {t.name: t.level_cm for t in task.tubes}
    outs = [outcome(task, dict(levels), tube, obj) for tube, obj in opts]
    rises = [float(o["reward_rise_cm"]) for o in outs]
    reached = [bool(o["reached"]) for o in outs]
    named = set(map(tuple, getattr(task, "correct", ()) or ()))
    correct = ({i for i, (t, o) in enumerate(opts) if (t.name, o.name) in named} or
               {i for i, r in enumerate(reached) if r} or {i for i, r in enumerate(rises) if r == max(rises)})
    options = [(perceive or perceived)(task, tube, obj) for tube, obj in opts]
    return options, (lambda i: (rises[i], reached[i])), correct, opts


def run_task(task, model: str, seeds: list[int], orders: int, ablate: tuple = (), trials: int = TRIALS,
             outcome=None, perceive=None, aim: str = "gap") -> dict:
    """Agents over seeds x orders on one task. Exploration: the task file's train objects dropped into every open tube,
    in a random order per agent (as the runner explores its train objects), then the trials. outcome: the world
    (default sim.apparatus.outcome); perceive(task, tube, obj): an option's measurement (default `perceived`, from
    the task file; train/task_run.py's, from the camera); aim: what a choice aims at (play)."""
    if outcome is None:
        from sim.apparatus import outcome
    options, world, correct, opts = task_world(task, outcome, perceive)
    train = list(getattr(task, "train", ()))
    right, choices = [], []
    for s in seeds:
        agent = context_agent(make_config(model, ablate, seed=s, extra=len(train) * len(task.tubes) + trials + 8),
                              orders)
        explore_opts = [(tube, obj) for obj in train for tube in task.tubes if getattr(tube, "open", True)]
        levels = {t.name: t.level_cm for t in task.tubes}
        ex = [(perceive or perceived)(task, tube, obj) for tube, obj in explore_opts]
        ex_out = [outcome(task, dict(levels), tube, obj) for tube, obj in explore_opts]
        all_opts = options + ex
        full_world = lambda i: world(i) if i < len(options) else (float(ex_out[i - len(options)]["reward_rise_cm"]),
                                                                  bool(ex_out[i - len(options)]["reached"]))
        rng = random.Random(s * 7919 + 1)
        explore = []
        for _ in range(orders):
            order = list(range(len(options), len(all_opts)))
            rng.shuffle(order)
            explore.append(order)
        r, c = play(agent, all_opts, full_world, correct, explore, trials, seed=s, offered=len(options), aim=aim)
        right += r
        choices += c
    return {"right": right, "choices": choices, "chance": 1.0 / len(options), "scores": score(right, 1 / len(options)),
            "options": [f"{t.name}:{o.name}" for t, o in opts], "correct": sorted(correct)}
