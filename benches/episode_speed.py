"""Wall time of one headless drop episode (the paper's heavy red cylinder), pick to settle.

    python benches/episode_speed.py

Prints the world's build time, the episode's wall time, how much simulated time it covered and what it measured;
the last line is `episode_wall_s=X`. (Printed, never asserted: speed depends on the machine.)
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.objects import DEFAULT_OBJECTS_FILE, load_objects  # noqa: E402
from sim.world import World  # noqa: E402
from record import recorded  # noqa: E402   # benches/record.py: keeps BENCHMARKS.md current


def main():
    t0 = time.perf_counter()
    world = World(load_objects(DEFAULT_OBJECTS_FILE))
    build = time.perf_counter() - t0
    world.run_episode("red_light_cylinder")  # warm-up: first-call costs (IK graph, caches) out of the figure
    steps0 = world.steps
    out = world.run_episode("red_heavy_cylinder")
    steps = world.steps - steps0
    sim_s = steps * world.config.tank.timestep_s
    t0 = time.perf_counter()
    world.goal_reachable()
    reach = time.perf_counter() - t0
    world.close()
    print(f"world build            {build:7.2f} s")
    print(f"episode                {out.wall_s:7.2f} s wall for {sim_s:.1f} s simulated ({steps} steps, "
          f"{1e3 * out.wall_s / steps:.2f} ms per step incl. IK and goal checks)")
    print(f"goal check             {1e3 * reach:7.1f} ms")
    print(f"observed {out.observed_cm3:.2f} cm^3, Archimedes {out.archimedes_cm3:.2f} cm^3, "
          f"felt {out.measurement['mass_g']:.1f} g, goal before/after {out.goal_reachable_before}/"
          f"{out.goal_reached_after}, settled {out.settled}")
    print(f"episode_wall_s={out.wall_s:.3f}")


if __name__ == "__main__":
    with recorded("episode_speed"):
        main()
