"""Goal trials with a learned model: choose what to drop from memory, drop, observe, learn, until the ball is reachable.

A trial (sim/trial.py): the ball starts out of reach, several objects wait on the stand, the jar is not reset
between drops. Each of the B agents (one per order) plays the trial on its own:
  lift and weigh every candidate (its measurement), anticipate its displacement from memory (Agent.anticipate),
  choose, drop it, read the rise, apply the rules and encode (Agent.step: learning stays on, a surprise teaches),
  and repeat until the ball is reachable or the stand is empty.

The choice comes from the model, never from the answer. The teacher issues the goal in words (default
DEFAULT_GOAL, or the trial's own phrase): heard through the word map, it drives the body hub's goal state, which
cues the episodic memory through the body rows (Agent.hear_goal, Agent.goal_recall), and the agent's estimate of the
rise the goal needs is read from the episodes that come back: the displacements that did and did not make the ball
reachable (each episode stores the body state after the drop). A phrase that names no goal the agent knows is
refused (ValueError, one line): the agent does not try what it was not asked. The choice is the candidate with the
fewest expected drops to close the remaining gap (1 if its anticipated displacement closes it, else 1 + the fewest
of the rest), ties to the largest displacement it expects over the two fates the object may meet, each at the
probability the agent gives it (Anticipation.by_fate, p_sink: an object between a floater and a sinker of its size
may go either way); with no estimate of the need yet, simply the largest.
An agent that recalls nothing for any candidate (a novice) explores: a random choice from a generator seeded by the
run's seed and the trial. How sure each anticipation is goes into the record: the strongest recall's strength and
how many recalled episodes agree with it.

Trials run after the exploration, on a copy of each agent with room for the trials' episodes and objects: the
run's checkpoint stays the state after the exploration, and the trials are a function of it (a resumed run plays
them the same). Within a run the trials follow each other, so what one trial taught is known in the next.
"""

from __future__ import annotations

import math

import torch

from aesop_torch.agent import GOAL_STATE, ROW_BODY_END, Agent
from aesop_torch.encoders import GOAL_WORDS
from aesop_torch.rules import contradiction
from sim.objects import DEFAULT_GOAL
from sim.trial import fewest_drops, optimal_first, random_drops_mean, reach_cm3
from train.learning.experiment import stack_measurements

TRIAL_SEED = 0x7121A1   # mixed into the run's seed for the novice's random choices


def roomy_copy(agent: Agent, extra: int) -> Agent:
    """A copy of `agent` (every learned buffer) whose memory holds `extra` more episodes and whose hub `extra` more
    objects (the run sizes both to the train objects). The property maps are shared: they never change."""
    import copy
    config = copy.deepcopy(agent.config)
    config.memory.max_episodes += extra
    config.hub.max_assemblies += extra
    new = Agent(config, batch=agent.batch, develop=False)
    new.maps = agent.maps
    for part in ("hub", "memory", "rules"):
        src, dst = getattr(agent, part), getattr(new, part)
        for key, value in src.state_dict().items():
            target = getattr(dst, key)
            with torch.no_grad():
                target[tuple(slice(0, n) for n in value.shape)] = value
    return new


def needed_cm3(agent: Agent, goal: str = DEFAULT_GOAL) -> torch.Tensor:
    """(B,) the displacement each agent expects the goal to need, from the episodes the goal phrase recalls
    (Agent.goal_recall): midway between the largest recalled displacement that left the ball out of reach and the
    smallest that made it reachable (only the latter if none failed below it); inf where no recalled drop reached
    the ball (the agent does not know yet). ValueError (one line) if the phrase names no goal the agent knows."""
    heard = agent.hear_goal(goal)
    if not bool(heard.known.all()):
        raise ValueError(f"{goal!r} is no goal I know: I can reach the ball (a goal says "
                         f"{' and '.join(map(repr, GOAL_WORDS))})")
    recall = agent.goal_recall(heard)
    reward = agent.reward.decode(agent._reward_row(recall.episodes))            # (B, K), NaN if not valid
    ok = recall.valid & ~torch.isnan(reward)
    holds = (recall.episodes[:, :, ROW_BODY_END] == agent.body.encode(GOAL_STATE)).all(-1)
    reached, missed = ok & holds, ok & ~holds
    inf = torch.full_like(reward, math.inf)
    hi = torch.where(reached, reward, inf).amin(-1)                             # (B,)
    lo = torch.where(missed & (reward < hi[:, None]), reward, -inf).amax(-1)
    return torch.where(torch.isfinite(lo) & torch.isfinite(hi), (lo + hi) / 2, hi)


def _expected_drops(expected: list[float], gap: float) -> list[float]:
    """Per candidate, the drops the agent expects if it drops that one now (NaN anticipations count as 0)."""
    e = [0.0 if math.isnan(x) else x for x in expected]
    if not math.isfinite(gap):
        return [math.inf] * len(e)
    out = []
    for i, x in enumerate(e):
        rest = e[:i] + e[i + 1:]
        if x >= gap:
            out.append(1.0)
        elif rest and sum(rest) + x >= gap:
            out.append(1.0 + fewest_drops(rest, gap - x))
        else:
            out.append(math.inf)
    return out


def choose(expected: list[float], gap: float, generator: torch.Generator,
           average: list[float] | None = None) -> tuple[int, bool, list[float]]:
    """(index chosen, explored, expected drops per candidate). See the module docstring. average (optional): per
    candidate the displacement expected over the fates it may meet; ties in drops go to the largest of it (default:
    the anticipated displacement itself)."""
    if all(math.isnan(x) for x in expected):
        return int(torch.randint(len(expected), (1,), generator=generator)), True, [math.nan] * len(expected)
    drops = _expected_drops(expected, gap)
    average = expected if average is None else average
    key = lambda i: (math.isnan(expected[i]), drops[i], -average[i])
    return min(range(len(expected)), key=key), False, drops


def run_trials(agent: Agent, stands: list[tuple], measurements: dict, drop, jar, archimedes: dict, seed: int = 0,
               names: bool = True, goals: list[str | None] | None = None) -> list[list[dict]]:
    """Play every trial in turn with each of the agent's B agents (learning on, carried from trial to trial).

    stands: per trial the names on the stand. measurements: name -> plain measurement (the candidate lifted and
    weighed). drop(sequences) -> per sequence {"observed_cm3", "goal_before", "goal_after", "sank"[, "measurement"]}:
    what the world reports for the last drop of each sequence (an agent's drops so far in this trial, in order; one
    call per round with the sequence of every agent still playing, so the world can simulate them together). archimedes:
    name -> true displacement, for the planner and the random chooser only. names: the teacher names each object
    as it is presented (its name as words). goals: per trial the teacher's goal phrase (None: DEFAULT_GOAL); a
    phrase that names no goal is refused (ValueError) before any trial is played. Returns per agent the list of
    trial records (CONTRACTS.md)."""
    B = agent.batch
    goals = [g or DEFAULT_GOAL for g in (goals or [None] * len(stands))]
    if len(goals) != len(stands):
        raise ValueError(f"{len(goals)} goals for {len(stands)} trials")
    # each goal heard and recalled once, before the trials: a trial's later drops start from a raised level, so the
    # goal state stored with them does not tell what rise one drop from the start level needs
    needs = {g: needed_cm3(agent, g) for g in dict.fromkeys(goals)}
    goal_cm3 = reach_cm3(jar)
    records = [[] for _ in range(B)]
    tol = agent.config.rules
    for i, stand in enumerate(stands):
        need = needs[goals[i]]
        g = torch.Generator().manual_seed((seed * 1_000_003 + TRIAL_SEED + i) % (2 ** 63))
        left = [list(stand) for _ in range(B)]
        seq = [[] for _ in range(B)]
        total = [0.0] * B
        rec = [{"goal": goals[i], "stand": list(stand), "chosen": [], "expected_cm3": [], "observed_cm3": [],
                "recall_strength": [], "agreeing_episodes": [], "expected_drops": [], "explored": []} for _ in range(B)]
        active = [True] * B
        while any(active):
            # anticipate every candidate on the stand, all agents at once (each agent's own candidates)
            width = max(len(left[b]) for b in range(B) if active[b])
            exp = torch.full((B, width), math.nan)
            average = torch.full((B, width), math.nan)
            strength = torch.zeros(B, width)
            agree = torch.zeros(B, width, dtype=torch.long)
            for j in range(width):
                ms = [measurements[left[b][j]] if active[b] and j < len(left[b]) else measurements[stand[0]]
                      for b in range(B)]
                a = agent.anticipate(_with_names(ms, [left[b][j] if active[b] and j < len(left[b]) else stand[0]
                                                      for b in range(B)], names), decoded=False)
                exp[:, j] = a.expected
                # over both fates where both have a fit, each at the probability the agent gives it
                both = a.p_sink * a.by_fate[:, 1] + (1 - a.p_sink) * a.by_fate[:, 0]
                average[:, j] = torch.where(torch.isnan(both), a.expected, both)
                valid = a.recall.valid & ~torch.isnan(a.rewards)
                strength[:, j] = (a.recall.strength * valid).amax(-1)
                agree[:, j] = (valid & ~contradiction(a.expected[:, None], a.rewards, tol)).sum(-1)
            picks = [None] * B
            for b in range(B):
                if active[b]:
                    n = len(left[b])
                    e = exp[b, :n].tolist()
                    k, explored, drops = choose(e, float(need[b]) - total[b], g, average[b, :n].tolist())
                    picks[b] = left[b][k]
                    r = rec[b]
                    r["chosen"].append(picks[b])
                    r["expected_cm3"].append(None if math.isnan(e[k]) else round(e[k], 2))
                    r["recall_strength"].append(round(float(strength[b, k]), 4))
                    r["agreeing_episodes"].append(int(agree[b, k]))
                    r["expected_drops"].append(None if not math.isfinite(drops[k]) else int(drops[k]))
                    r["explored"].append(explored)
                    left[b].pop(k)
                    seq[b].append(picks[b])
            playing = [b for b in range(B) if active[b]]
            outs = [None] * B
            for b, o in zip(playing, drop([tuple(seq[b]) for b in playing])):
                outs[b] = o
            learn = torch.tensor(active)
            filler = next(o for o in outs if o is not None)
            outs_or = [o if o is not None else filler for o in outs]
            ms = [o.get("measurement") or measurements[picks[b] or stand[0]] for b, o in enumerate(outs_or)]
            agent.step(_with_names(ms, [picks[b] or stand[0] for b in range(B)], names),
                       torch.tensor([o["observed_cm3"] for o in outs_or]),
                       torch.tensor([o["goal_before"] for o in outs_or]),
                       torch.tensor([o["goal_after"] for o in outs_or]), learn=learn,
                       sank=torch.tensor([o["sank"] for o in outs_or]))
            for b in range(B):
                if active[b]:
                    o = outs[b]
                    total[b] += o["observed_cm3"]
                    rec[b]["observed_cm3"].append(round(o["observed_cm3"], 2))
                    rec[b]["goal_reached"] = bool(o["goal_after"])
                    active[b] = not o["goal_after"] and bool(left[b])
        volumes = [archimedes[n] for n in stand]
        best = fewest_drops(volumes, goal_cm3)
        first_ok = optimal_first(volumes, goal_cm3)
        for b in range(B):
            r = rec[b]
            r["drops"] = len(r["chosen"])
            r["fewest_drops"] = best
            r["random_drops_mean"] = round(random_drops_mean(volumes, goal_cm3), 4)
            r["excess_drops"] = r["drops"] - best
            r["first_choice_optimal"] = bool(first_ok[stand.index(r["chosen"][0])])
            records[b].append({k: r[k] for k in ("goal", "stand", "chosen", "expected_cm3", "observed_cm3", "drops",
                                                 "goal_reached", "fewest_drops", "random_drops_mean", "excess_drops",
                                                 "first_choice_optimal", "expected_drops", "recall_strength",
                                                 "agreeing_episodes", "explored")})
    return records


def _with_names(ms: list[dict], names: list[str], on: bool) -> dict:
    out = stack_measurements(ms)
    if on:
        out["words"] = list(names)
    return out


TRIAL_OUTCOME_KEYS = ("observed_cm3", "goal_before", "goal_after", "sank", "measurement")


def outcome_dict(outcome) -> dict:
    """The part of a world EpisodeOutcome a trial keeps (TRIAL_OUTCOME_KEYS). A goal trial's drop that was not
    delivered into the jar, or read a non-finite or negative volume, ends the run in one line (BadOutcome, as an
    episode's: train.learning.experiment.check_outcome) rather than teach the agent what the world did not do."""
    from train.learning.experiment import BadOutcome, plain_measurement
    cm3 = float(outcome.observed_cm3)
    if getattr(outcome, "delivered", True) is False or not math.isfinite(cm3) or cm3 < 0:
        raise BadOutcome(f"a goal trial's drop of {getattr(outcome, 'name', 'an object')!r} was not delivered into "
                         f"the jar or read {cm3!r} cm^3; its trial is not recorded")
    return {"observed_cm3": float(outcome.observed_cm3), "goal_before": bool(outcome.goal_reachable_before),
            "goal_after": bool(outcome.goal_reached_after), "sank": bool(outcome.sank),
            "measurement": plain_measurement(outcome.measurement)}


def planner_sequences(objects) -> list[tuple]:
    """Per trial whose planner needs several drops, in the objects file's order, the drops it makes: the largest
    Archimedes displacement first, until the ball is reachable (sim.trial.fewest_drops). The runner simulates these
    ahead, while its workers would idle (play_trials' `ahead`): a well-taught agent chooses them."""
    from sim.objects import archimedes_cm3
    need = reach_cm3(objects.jar)
    out = []
    for stand in objects.trials:
        volume = {n: archimedes_cm3(objects.get(n), objects.jar) for n in stand}
        best = sorted(stand, key=lambda n: -volume[n])
        k = fewest_drops(list(volume.values()), need)
        if k > 1:
            out.append(tuple(best[:k]))
    return list(dict.fromkeys(out))


def play_trials(exp, objects, physics=None, first_drops: dict | None = None, progress=None,
                ahead: dict | None = None) -> list[list[dict]]:
    """The runner's goal trials: every trial of the objects file with every order's agent, in the simulated world
    (each drop into the jar as earlier drops of the trial left it, the IK reach test after each). A candidate is
    lifted and weighed as in the exploration (its measurement from there, or from a drop here for an object only
    trials use).

    Drops are cached by the sequence dropped so far in the trial (agents that chose alike share them); each round's
    new sequences are simulated together on `physics` (train.learning.sim_pool.Physics: the runner's worker pool; default one
    in this process, closed after), each from a fresh jar. first_drops: name -> outcome record of that object dropped
    into a fresh jar of this world with this seed (the runner's cached exploration drops, and the drops that measured
    its probes that wait on a stand): a trial's first drop of it is that same drop, bit for bit
    (tests/test_trials.py), so it is not simulated again. ahead: sequence -> a result started earlier
    (Physics.ahead, e.g. of planner_sequences): taken instead of simulating that sequence when an agent drops it.
    Neither changes an outcome: each sequence starts from a fresh jar wherever and whenever it is simulated."""
    from sim.objects import archimedes_cm3
    from train.learning.sim_pool import Physics

    own = physics is None
    physics = Physics(objects, seed=exp.seed, workers=1) if own else physics
    try:
        measurements = {n: o["measurement"] for n, o in exp.outcomes.items()}
        measurements.update({n: p["measurement"] for n, p in exp.probes.items()})
        cache = {(n,): {k: o[k] for k in TRIAL_OUTCOME_KEYS} for n, o in (first_drops or {}).items()}
        # an object only the trials use is measured by a drop into a fresh jar: the same look, take, lift and weigh
        # as an inspection, so the same measurement bit for bit (tests/test_world.py), and a trial's first drop of it
        unseen = [n for n in dict.fromkeys(n for stand in objects.trials for n in stand)
                  if n not in measurements and (n,) not in cache]
        for n, (outcome,) in zip(unseen, physics.run([("trial", (n,), None) for n in unseen])):
            cache[(n,)] = outcome_dict(outcome)
        measurements.update({s[0]: o["measurement"] for s, o in cache.items() if s[0] not in measurements})
        archimedes = {n: archimedes_cm3(objects.get(n), objects.jar) for stand in objects.trials for n in stand}
        agent = roomy_copy(exp.agent, sum(len(s) for s in objects.trials))

        started = dict(ahead or {})
        extending = lambda s: next((t for t in started if t[:len(s)] == s), None)   # a started sequence from s on

        def drop(sequences):
            new = [s for s in dict.fromkeys(sequences) if s not in cache]
            fresh = [s for s in new if extending(s) is None]
            submitted = physics.submit([("trial", s, None) for s in fresh])   # these start while we wait for the rest
            for s in new:
                if s in fresh:
                    whole, outs = s, next(submitted)
                elif s in cache:   # a prefix of a started sequence taken in this round
                    continue
                else:
                    whole = extending(s)
                    outs = started.pop(whole).get()
                for k in range(1, len(whole) + 1):
                    cache.setdefault(whole[:k], outcome_dict(outs[k - 1]))
            for s in sequences if progress is not None else ():
                progress(s)
            return [cache[s] for s in sequences]

        return run_trials(agent, objects.trials, measurements, drop, objects.jar, archimedes, seed=exp.seed,
                          goals=objects.goals)
    finally:
        if own:
            physics.close()
