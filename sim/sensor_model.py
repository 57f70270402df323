"""One noise model for what the robot senses, for the paths that run without the simulator.

The population, the tests and the benches need perceived values and measured outcomes for many objects without
simulating every one. They draw them here, from the object's true geometry plus noise whose sizes are those of the
simulated robot's senses (the camera's colour, extents and fill, the hand's felt mass, the water level read off the
jar), so their figures stand for the robot the runner really simulates. `benches/perception.py` measures the
perception errors and `tests/test_sensor_model.py` ties these numbers to the simulator.

Each object's draws come from a generator seeded by (seed, object name), as the world seeds a drop's sensor noise,
so an object is perceived the same whatever else is drawn and in whatever order.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from sim.objects import JarSpec, ObjectSpec, archimedes_cm3


@dataclass(frozen=True)
class SensorModel:
    # colour: the mean of the object's pixels under flat light; per channel, absolute (0..1)
    rgb_sd: float = 0.01
    # extents: relative error of each side measured from the depth image
    extent_rel_sd: float = 0.01
    # fill (volume / bounding box): absolute error of the shape descriptor
    fill_sd: float = 0.01
    # felt mass: the wrist sensor's ~0.01 N (sim/world.py WorldConfig.mass_noise_g)
    mass_sd_g: float = 1.0
    # displaced volume: the simulated water's deviation from Archimedes, relative, plus the level reading's
    # resolution in cm^3 (0.001 cm of level in a 12 cm jar is 0.11 cm^3)
    outcome_rel_sd: float = 0.005
    outcome_abs_sd_cm3: float = 0.1

    def rng(self, seed: int, name: str) -> np.random.Generator:
        return np.random.default_rng([seed, zlib.crc32(name.encode())])

    def measure(self, spec: ObjectSpec, rng: np.random.Generator) -> dict:
        """What the robot perceives of `spec`: {rgb, extent_cm (sorted descending), fill, mass_g}, plain floats."""
        rgb = np.clip(np.asarray(spec.rgb) + rng.normal(0.0, self.rgb_sd, 3), 0.0, 1.0)
        ext = np.sort(spec.extent_cm * (1.0 + rng.normal(0.0, self.extent_rel_sd, 3)))[::-1]
        fill = float(np.clip(spec.fill + rng.normal(0.0, self.fill_sd), 0.05, 1.0))
        mass = max(0.1, spec.mass_g + float(rng.normal(0.0, self.mass_sd_g)))
        return {"rgb": [float(x) for x in rgb], "extent_cm": [float(x) for x in ext], "fill": fill,
                "mass_g": float(mass)}

    def observe(self, spec: ObjectSpec, jar: JarSpec, rng: np.random.Generator) -> float:
        """The displaced volume the robot reads off the jar for `spec`, in cm^3."""
        v = archimedes_cm3(spec, jar)
        return float(max(0.0, v * (1.0 + rng.normal(0.0, self.outcome_rel_sd))
                         + rng.normal(0.0, self.outcome_abs_sd_cm3)))
