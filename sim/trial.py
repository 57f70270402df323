"""Goal trials: the ball starts out of reach, the stand holds several objects, and the water is NOT reset between the
drops of one trial. The robot drops objects one at a time until the ball is reachable or the stand is empty.

What lives here is the world's side of a trial and its yardsticks, never the agent's choice (train/learning/goal_trials.py):
- `drop_next` (physics): one drop into the jar as it is, every object dropped before still in it; the same look,
  take, lift, weigh, carry and release as `sim.episode.drop_episode`, and the same IK reach test after it.
  The stand is a pedestal for one object: the other candidates wait beside it (not simulated) and the one chosen
  is put on the stand when its turn comes.
- `closed_form_drop`: the same trial without physics (benches, tests): each object displaces its Archimedes volume
  (or a sensed value), displacements add up, and the ball is reachable once the water rose `reach_rise_cm`.
- `fewest_drops` (a planner that knows Archimedes and the true masses) and `random_drops_mean` (a chooser at random,
  computed exactly): the yardsticks a trial's drops are compared with.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from sim.objects import JarSpec, ObjectsConfig


@dataclass(frozen=True)
class TrialConfig:
    # the ball is reachable once its top floats up to the rim, measured "from 0-2 mm below the rim on"
    # (sim/world.py): the closed form calls it reachable 1 mm below, the middle of that band
    reach_below_rim_cm: float = 0.1
    # the world's ping-pong ball (sim/water.py TankConfig): 4 cm, 2.7 g
    ball_diameter_cm: float = ObjectsConfig.ball_diameter_cm
    ball_mass_g: float = 2.7


def reach_rise_cm(jar: JarSpec, config: TrialConfig = TrialConfig()) -> float:
    """How far the water must rise from its start level before the ball is reachable (closed form): the ball's top
    starts at depth + diameter - draft (a floating sphere's cap holds its mass of water) and must come within
    `reach_below_rim_cm` of the rim. Default jar: 14 + 4 - 0.68 = 17.32 cm, rim 19.5 cm: 2.08 cm (235 cm^3)."""
    r, v = config.ball_diameter_cm / 2, config.ball_mass_g
    lo, hi = 0.0, 2 * r
    for _ in range(60):   # the cap's depth h: pi h^2 (3 r - h) / 3 = v
        h = 0.5 * (lo + hi)
        lo, hi = (h, hi) if math.pi * h * h * (3 * r - h) / 3 < v else (lo, h)
    top = jar.water_depth_cm + 2 * r - 0.5 * (lo + hi)
    return jar.height_cm - config.reach_below_rim_cm - top


def reach_cm3(jar: JarSpec, config: TrialConfig = TrialConfig()) -> float:
    """The displaced volume that makes the ball reachable (closed form): reach_rise_cm x the jar's cross-section."""
    return reach_rise_cm(jar, config) * jar.area_cm2


def drops_to_goal(volumes, need_cm3: float) -> int:
    """Drops of the objects in this order until their volumes add up to need_cm3; all of them if they never do."""
    total = 0.0
    for k, v in enumerate(volumes, 1):
        total += v
        if total >= need_cm3:
            return k
    return len(volumes)


def fewest_drops(volumes, need_cm3: float) -> int:
    """The planner that knows every object's displacement: the largest first is optimal (no k objects add up to more
    than the k largest), so the fewest drops is drops_to_goal on the volumes sorted in descending order."""
    return drops_to_goal(sorted(volumes, reverse=True), need_cm3)


def optimal_first(volumes, need_cm3: float) -> list[bool]:
    """Which objects a planner may drop first and still reach the goal in the fewest drops."""
    best = fewest_drops(volumes, need_cm3)
    rest = lambda i: [v for j, v in enumerate(volumes) if j != i]
    return [(volumes[i] >= need_cm3 and best == 1) or
            (volumes[i] < need_cm3 and len(volumes) > 1 and 1 + fewest_drops(rest(i), need_cm3 - volumes[i]) == best)
            or (len(volumes) == 1) for i in range(len(volumes))]


def random_drops_mean(volumes, need_cm3: float) -> float:
    """The expected drops of a chooser that picks uniformly at random, exactly: a random order drops its (k+1)-th
    object iff its first k did not reach the goal, so E[drops] = sum_{k=0}^{n-1} P(a random k-subset falls short),
    each probability counted over all C(n, k) subsets."""
    n = len(volumes)
    total = 0.0
    for k in range(n):
        subsets = list(itertools.combinations(volumes, k))
        total += sum(sum(s) < need_cm3 for s in subsets) / len(subsets)
    return total


def heaviest_first(masses) -> int:
    """The index a 'heaviest first' chooser picks (ties to the first listed)."""
    return int(np.argmax(np.asarray(masses, dtype=float)))


def closed_form_drop(outcomes: dict, need_cm3: float):
    """A trial's drops without physics: drop(sequences) -> per sequence, what the world reports for its last drop
    (train.learning.goal_trials.run_trials' drop).

    outcomes: name -> that object's exploration outcome (train.learning.experiment.outcome_record or closed_form_outcomes):
    its observed_cm3 (sensed, or Archimedes) and sank are reused, displacements add up in the jar, and the ball is
    reachable once their sum reaches need_cm3 (reach_cm3)."""
    def one(sequence) -> dict:
        *before, last = sequence
        total = sum(float(outcomes[n]["observed_cm3"]) for n in before)
        o = outcomes[last]
        return {"observed_cm3": float(o["observed_cm3"]), "goal_before": total >= need_cm3,
                "goal_after": total + float(o["observed_cm3"]) >= need_cm3, "sank": bool(o["sank"])}
    return lambda sequences: [one(s) for s in sequences]


# -- physics --------------------------------------------------------------------------------------------------------

def drop_next(world, name: str, record=None):
    """One drop of a goal trial (World.drop_next): the named object is put on the stand and dropped into the jar as
    it is (what earlier drops of the trial left in it stays). The sensor noise is seeded by (seed, name) as in an
    exploration drop, so the object is perceived as it was then. Returns a sim.episode.EpisodeOutcome whose
    observed_cm3 is this drop's rise of the level alone."""
    from sim.episode import drop_into_jar

    world.seed_noise(name)
    return drop_into_jar(world, name, record)


def simulate_sequence(world, names, record=None) -> list:
    """Drop `names` one after another into a fresh jar (World.reset, then World.drop_next each): their outcomes. The
    runner simulates a trial's sequences this way on its worker pool (train/learning/sim_pool.py, train/learning/goal_trials.py)."""
    world.reset()
    return [world.drop_next(n, record) for n in names]
