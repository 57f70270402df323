"""One config for a run, settable without code: the agent's and the world's, from a TOML file and `--set` overrides.

A key is a dotted path of dataclass fields, the same everywhere (`--set`, the TOML file, `apply_overrides`, the
`config` of summary.json):

* the agent's config, `aesop_torch.agent.AgentConfig`: its own fields at the top level (`recall_sharpness`,
  `compare_with`, `model`, `ablate`, `seed`, ...) and its parts by name (`encoder.`, `hub.`, `memory.`, `rules.`);
* the world's config under `world.`: `sim.world.WorldConfig`, the pybullet scene every physics worker of the runner
  builds (`World(objects, config, seed)`, train/learning/sim_pool.py), with its parts `world.tank.` (`sim.water.TankConfig`:
  jar, ball, stepping), `world.tank.water.` (`WaterConfig`), `world.robot.` (`sim.robot.RobotConfig`), `world.ik.`
  (`sim.kinematics.IKConfig`) and `world.camera.` (`sim.perception.CameraConfig`); e.g. `world.mass_noise_g`, the
  wrist's noise on the felt mass. The runner builds no other world config: `sim.sensor_model.SensorModel` serves
  only the paths without the simulator (population, benches, sweeps), and `sim.objects.ObjectsConfig` holds the
  objects file's bounds, which sim/world.py and sim/water.py read from the class, so an instance would not reach
  them.

A TOML file mirrors the dataclasses: top-level keys are AgentConfig fields, tables its parts and the world's:

    model = "extended"
    ablate = ["rules"]
    recall_sharpness = 8
    [rules]
    uncertain_decay = 1.0
    [memory]
    max_recalls = "none"
    [world]
    mass_noise_g = 5
    [world.tank.water]
    density = 998.0

Values: a float field takes any number (an integer too), an int field an integer (not 1.0), a bool field `true` or
`false`, a str field a string; a tuple field an array (of arrays for pairs such as `delta_p_band`); an `int | None`
field also the string "none" (TOML has no null; in-process, None). NaN and infinities are refused everywhere, and a
negative integer (every int field is a count, a size or a seed). Where a dataclass validates itself (its
__post_init__) its ValueError becomes a ConfigError naming the key; `RANGES` adds the bounds a field's meaning gives
it (a standard deviation >= 0, a time step > 0, ...), each group with its reason; no other range is invented.
`model` switches the named constructor (`AgentConfig.named`: the extended model compares with every recalled
episode), keeping every field the config had changed from its model's defaults.

    resolve(overrides) -> RunConfig(agent, world)      what the runner uses: the defaults (the paper model, the
                                                       world as built) with the overrides applied, in order
    apply_overrides(agent_config, overrides)            a new AgentConfig (agent keys only)
    apply_world_overrides(world_config, overrides)      a new WorldConfig (`world.` keys only)
    config_dict(config)                                 plain JSON-able data in the TOML file's layout
    parse_set("k=v") -> (key, value), load_toml(path) -> {dotted key: value}

Nothing here imports torch or pybullet at module level: the runner parses its flags and reads its --config file
before its first line (train/run.py), and the functions that need the dataclasses are given instances or import
them when called.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import os
import re
import stat
import types
import typing
from dataclasses import dataclass
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10, pyproject's floor: the same parser as a package (a declared dependency)
    import tomli as tomllib

WORLD = "world"                   # the world's keys: world.<field>, [world] in a file
NONE = "none"                     # how a file or --set says None for an `int | None` field
MAX_TOML_BYTES = 1_000_000        # a config is a few hundred bytes; a file far beyond is not one (read no further)
KEY_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*", re.ASCII)
BARE_WORD_RE = re.compile(r"[A-Za-z0-9_.+-]+", re.ASCII)   # --set key=word: a string without quotes
MAX_SEED = 2 ** 63                # the run's seed: torch.Generator.manual_seed takes 64 bits, stored as int64

# Bounds a field's meaning gives it, beyond what its dataclass checks: (low, low included, high or None). Integers
# are never negative (each is a count, a size or a seed); these are the ones that must be at least 1 or more.
POSITIVE, NON_NEGATIVE, AT_LEAST_ONE, FRACTION = (0, False, None), (0, True, None), (1, True, None), (0, True, 1)
RANGES = {
    # the encoder reads sizes and masses in logs between these bounds (encoders._log_unit); developmental shapes
    # are log-uniform in [1 / max_aspect, max_aspect], an interval only from 1 up
    "encoder.size_min_cm": POSITIVE, "encoder.size_max_cm": POSITIVE, "encoder.mass_min_g": POSITIVE,
    "encoder.mass_max_g": POSITIVE, "encoder.max_aspect": AT_LEAST_ONE,
    # sizes of tensors: neurons, rows, assemblies, episodes, chunks, samples, epochs
    # the hub is the sheet's 12 object rows (hub.rows x hub.n_neurons = 12 x memory.cols, at most 12 x 1000 below);
    # a memory and a hub hold at most the objects of one life (sim.objects.ObjectsConfig.max_objects, 2000), and an
    # episode is compared with at most the episodes they hold
    "hub.n_neurons": (1, True, 12_000), "hub.assembly_size": (1, True, 12_000), "hub.rows": (1, True, 12_000),
    "hub.max_assemblies": (1, True, 2000), "memory.max_episodes": (0, True, 2000),
    # the sheet's neurons (memory.rows x memory.cols: the paper's 20 x 50) are each driven by every other in a recall
    # step, so its work grows as their square: 100 x 1000 is 10^4x the paper's (the hub is the sheet's object rows,
    # hub.rows x hub.n_neurons = 12 x memory.cols, so this bounds it too); a recall step settles in ~5 clamped and ~2
    # free steps (aesop_torch/memory.py), 1000 of either is a recall that does not settle; a chunk of 2^31 elements
    # is 8 GB of float32 working tensors at once
    "memory.rows": (1, True, 100), "memory.cols": (1, True, 1000), "memory.cue_steps": (0, True, 1000),
    "memory.free_steps": (0, True, 1000), "memory.misses": (0, True, 1000),
    "memory.chunk_agents": (1, True, 1 << 20), "memory.chunk_elements": (1, True, 1 << 31),
    # the maps' developmental samples are held at once (1e6 x the 22-d word map's inputs x 4 bytes: 88 MB) and each
    # epoch is a pass over them; 4000 x 30 (the defaults) take ~0.3 s, so the bounds' product is about an hour
    "som_samples": (1, True, 1_000_000), "som_epochs": (1, True, 10_000),
    # a fraction of the bump's peak; certainty after n firings is 1 - (1 - step)^n, in 0..1 only for a step in 0..1
    "hub.store_floor": FRACTION, "rules.certainty_step": FRACTION,
    # the cue relative to its peak raised to this power: <= 0 would invert or flatten it; a strength floor
    "memory.cue_power": POSITIVE, "memory.min_strength": NON_NEGATIVE,
    # pathway strengths and their factors multiply an activity (a negative one flips its sign); tolerances and
    # floors compare magnitudes; ridges are added to a fit's diagonal (a negative one can make it singular)
    "rules.eliminated_strength": NON_NEGATIVE, "rules.dominant_strength": NON_NEGATIVE,
    "rules.growth_step": NON_NEGATIVE, "rules.uncertain_floor": NON_NEGATIVE,   # uncertain_decay, contradiction_rel:
    "rules.same_abs_cm3": NON_NEGATIVE, "rules.same_rel": NON_NEGATIVE,          # fractions (below)
    "rules.contradiction_abs_cm3": NON_NEGATIVE, "retro_floor": NON_NEGATIVE, "readout_ridge": NON_NEGATIVE,
    "fate_ridge": NON_NEGATIVE, "fate_boundary_ridge": NON_NEGATIVE,
    # a standard deviation; the readout divides by these two
    "felt_mass_noise_g": NON_NEGATIVE, "readout_rel_precision": POSITIVE, "readout_huber": POSITIVE,
    # the world: standard deviations of the senses' noise (numpy refuses a negative scale)
    "world.mass_noise_g": NON_NEGATIVE, "world.level_noise_cm": NON_NEGATIVE,
    # what the hand reports is floored here (SensorModel.min_felt_mass_g: the encoders refuse a mass <= 0); the level
    # is read to this step
    "world.min_felt_mass_g": POSITIVE, "world.level_resolution_cm": POSITIVE,
    # durations, time steps and time constants (drag divides by them); pybullet reads a mass of 0 as "static"
    "world.tank.timestep_s": POSITIVE, "world.tank.settle_timeout_s": POSITIVE, "world.move_timeout_s": POSITIVE,
    "world.tank.water.drag_time_s": POSITIVE, "world.tank.water.angular_drag_time_s": POSITIVE,
    "world.tank.ball_mass_g": POSITIVE, "world.robot.phantom_mass_kg": POSITIVE, "world.tank.water.density": POSITIVE,
    # lengths of solid things (the world checks table_top_z and stand_height itself, in its workers: here first)
    "world.tank.wall_thickness_cm": POSITIVE, "world.tank.bottom_thickness_cm": POSITIVE,
    "world.tank.ball_diameter_cm": POSITIVE, "world.table_top_z": POSITIVE, "world.table_thickness": POSITIVE,
    "world.stand_height": POSITIVE, "world.stand_radius": POSITIVE, "world.camera.near": POSITIVE,
    "world.camera.far": POSITIVE, "world.camera.side_distance": POSITIVE, "world.camera.top_distance": POSITIVE,
    "world.camera.side_field_cm": POSITIVE, "world.camera.top_field": POSITIVE,
    # gaps, clearances, margins, tolerances, thresholds of stillness, frictions, gains, forces, damping: magnitudes
    "world.ball_gap_cm": NON_NEGATIVE, "world.palm_face_cm": NON_NEGATIVE, "world.grasp_gap_cm": NON_NEGATIVE,
    "world.hover_cm": NON_NEGATIVE, "world.carry_clearance_cm": NON_NEGATIVE, "world.camera.top_pad_cm": NON_NEGATIVE,
    "world.joint_tol_rad": POSITIVE, "world.via_tol_rad": POSITIVE, "world.ik.pos_tol": POSITIVE,
    "world.ik.rot_tol": POSITIVE, "world.ik.reach_tol": NON_NEGATIVE, "world.ik.rot_weight": NON_NEGATIVE,
    "world.ik.damping": NON_NEGATIVE, "world.ik.lm_damping": NON_NEGATIVE, "world.ik.torso_scale": NON_NEGATIVE,
    "world.ik.max_err": POSITIVE, "world.ik.max_step": POSITIVE, "world.ik.stall_ratio": NON_NEGATIVE,
    "world.tank.object_friction": NON_NEGATIVE, "world.tank.wall_friction": NON_NEGATIVE,
    "world.tank.settle_speed_m_s": NON_NEGATIVE, "world.tank.settle_spin_rad_s": NON_NEGATIVE,
    "world.tank.settle_level_cm": NON_NEGATIVE, "world.tank.water.quadratic_drag": NON_NEGATIVE,
    "world.tank.water.heave_damping_ratio": NON_NEGATIVE, "world.tank.water.level_tolerance_m": NON_NEGATIVE,
    "world.tank.water.shortcut_margin_m": NON_NEGATIVE, "world.tank.water.level_band_m": NON_NEGATIVE,
    "world.robot.body_max_force": NON_NEGATIVE, "world.robot.position_gain": NON_NEGATIVE,
    "world.robot.velocity_gain": NON_NEGATIVE, "world.robot.max_velocity": POSITIVE,
    # counts of steps, iterations, points, pixels, waypoints that something is divided by, averaged or stepped over;
    # each bounded where more is only more work: a wait of the simulator at most 240,000 steps (1000 s of simulated
    # time, train/runner/config_checks.py WAIT_STEPS); pybullet's solver converges in its default 50 iterations; 60 IK
    # iterations solve every target the bench box reaches (sim/kinematics.py); the level's Newton iterations reach
    # its 0.1 nm tolerance in a handful (30 by default); 1000 waypoints are 0.3 mm apart on the 31 cm carry; a render
    # costs ~20 ms at 256 px and 64x that at 2048; 4096 points already sample a body's volume to 0.5 % (16x that)
    "world.tank.solver_iterations": (1, True, 1000), "world.tank.settle_window_steps": (1, True, 240_000),
    "world.tank.settle_windows": (1, True, 240_000), "world.tank.water.points_per_body": (1, True, 65_536),
    "world.tank.water.level_max_iterations": (1, True, 200), "world.ik.max_iters": (1, True, 10_000),
    "world.ik.check_every": (1, True, 10_000), "world.camera.width": (1, True, 2048),
    "world.waypoints": (1, True, 1000),
    # a 40-restart solve reaches no target the default 7 miss on the bench box (sim/kinematics.py)
    "world.ik.restarts": (0, True, 100),
    "world.weigh_steps": (1, True, 240_000), "world.weigh_wait_steps": (0, True, 240_000),
    "world.camera.min_pixels": (0, True, 2048 * 2048),
    # the jar's round wall is a polygon of this many staves (pybullet builds 16 to a link; 256 make the polygon's
    # area within 0.01 % of the circle's)
    "world.tank.staves": (3, True, 256),
    # the run's seed (the agent's is the run's: train.learning.experiment sets it) and the IK's restarts' generator's
    # (a torch.Generator takes 64 bits)
    "seed": (0, True, MAX_SEED - 1), "world.ik.seed": (0, True, MAX_SEED - 1),
    # episodes a recall brings back are at most those a memory holds (memory.max_episodes, at most 2000)
    "fate_recalls": (1, True, 2000), "memory.max_recalls": (1, True, 2000),
    # a match of the hub's relative activity (the same object shown again: 1, exactly or a hair less) and the word
    # maps' cosines (imagine_floor) and fraction of goal words heard (goal_floor) lie in 0..1: a threshold at or below
    # 0 takes every object for the first one (every phrase for a name, for the goal), one above 1 never matches
    "hub.match_threshold": (0, False, 1), "imagine_floor": (0, False, 1), "goal_floor": (0, False, 1),
    # "marginally reduce": a factor above 1 would grow an undecided pathway; the contradiction's relative tolerance
    # compares |observed - expected| with the larger of the two: beyond 1 nothing is ever off by that much (same_rel
    # is at most it: train/runner/config_checks.py)
    "rules.uncertain_decay": FRACTION, "rules.contradiction_rel": (0, True, 1, False),
    # a neuron's estimate of its own activity: 0 (off) .. 1 (on), a stored episode's own neurons exactly 1; a neuron
    # fires above the threshold, so at 1 or more none ever does (every recall empty, every prediction missing)
    "memory.threshold": (0, True, 1, False),
    # compared with no recalled episode, no rule ever fires (what --ablate rules says); none: with every one
    "compare_with": (1, True, 2000),
    # pulls down (the water's force and the hand's weighing divide by it; 0 or less: nothing falls into the jar)
    "world.tank.gravity": POSITIVE, "world.tank.water.gravity": POSITIVE,
}
# an int field without an upper bound above (a count, a size): at most this, what a 64-bit tensor or generator holds
MAX_INT = MAX_SEED - 1
# bounds of each element of a flat tuple field: colours are RGB(A) fractions; an arm motor without force never
# moves its joint (the object is never delivered, found at the first drop)
ELEMENT_RANGES = {"world.tank.jar_rgba": FRACTION, "world.tank.water_rgba": FRACTION, "world.tank.ball_rgb": FRACTION,
                  "world.robot.arm_max_force": POSITIVE}


class ConfigError(Exception):
    """A key or value the config does not take. str(e) is one line naming the key; `key` is that dotted key (None
    when the problem is no one key's, e.g. a file that is not TOML)."""

    def __init__(self, message: str, key: str | None = None):
        super().__init__(message)
        self.key = key


@dataclass
class RunConfig:
    """What a run is configured with: `agent`, the agents' `aesop_torch.agent.AgentConfig`, and `world`, the
    `sim.world.WorldConfig` every physics worker builds its scene from. `resolve` makes one; `config_dict` gives it
    as data in the TOML layout (the agent's keys at the top level, the world's under "world")."""
    agent: typing.Any
    world: typing.Any

    @classmethod
    def default(cls) -> "RunConfig":
        from aesop_torch.agent import AgentConfig
        from sim.world import WorldConfig
        return cls(AgentConfig.paper(), WorldConfig())


# -- reading: --set and TOML files ----------------------------------------------------------------------------------

def parse_set(text: str) -> tuple[str, object]:
    """`KEY=VALUE` -> (key, value): the value read as a TOML value (`1`, `0.5`, `true`, `"a b"`, `[1, 2]`,
    `[[0.1, 0.2]]`), a bare word (`extended`, `none`, `forget_oldest`) taken as a string. Only the syntax is checked
    here; whether the key exists and takes the value is `apply_overrides`' / `resolve`'s."""
    key, eq, value = text.partition("=")
    key = key.strip()
    if not eq:
        raise ConfigError(f"expected KEY=VALUE (e.g. rules.uncertain_decay=1.0), got {_show(text)}")
    if not KEY_RE.fullmatch(key):
        raise ConfigError(f"{_show(key)} is not a key: dotted names of letters, digits and _ (e.g. "
                          "rules.uncertain_decay)")
    return key, parse_value(value, key)


def parse_value(text: str, key: str = "value") -> object:
    """One TOML value, or a bare word as a string (see `parse_set`)."""
    if "\n" in text or "\r" in text:
        raise ConfigError(f"{key}: a value is one line, got {_show(text)}", key)
    word = text.strip()
    if not word:
        raise ConfigError(f"{key}: no value after '='", key)
    try:
        doc = tomllib.loads(f"v = {text}")
    except tomllib.TOMLDecodeError as e:
        if BARE_WORD_RE.fullmatch(word):
            return word
        raise ConfigError(f"{key}: {_show(text)} is not a TOML value (a string with spaces or symbols is quoted: "
                          f"{key}='\"a b\"')", key) from None
    except (RecursionError, ValueError, MemoryError) as e:   # [[[[...: nested too deep; 5000-digit integers
        raise ConfigError(f"{key}: {_show(text)} is not a value this config reads ({_one_line(e) or 'too deep'})",
                          key) from None
    if set(doc) != {"v"}:
        raise ConfigError(f"{key}: {_show(text)} is more than one value", key)
    return doc["v"]


def load_toml(path) -> dict:
    """A TOML config file -> {dotted key: value} (tables flattened: `[rules] uncertain_decay = 1` gives
    "rules.uncertain_decay"), in the file's order. ConfigError (one line starting with the path) for a file that is
    missing, not a regular file, over MAX_TOML_BYTES, not UTF-8 or not TOML."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read it ({e.strerror or e})") from None
    if not stat.S_ISREG(st.st_mode):   # a directory, a device (/dev/zero never ends) or a pipe (may never open)
        raise ConfigError(f"{path}: not a regular file")
    if st.st_size > MAX_TOML_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_TOML_BYTES:,} bytes, not a config file")
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_TOML_BYTES + 1)
    except OSError as e:
        raise ConfigError(f"{path}: cannot read it ({e.strerror or e})") from None
    if len(data) > MAX_TOML_BYTES:
        raise ConfigError(f"{path}: larger than {MAX_TOML_BYTES:,} bytes, not a config file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not UTF-8 text (byte {e.start})") from None
    try:
        return flatten(tomllib.loads(text))
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: {_repeated(text, e) or 'not valid TOML: ' + _one_line(e)}") from None
    except (RecursionError, ValueError, MemoryError) as e:
        raise ConfigError(f"{path}: not a file this config reads ({_one_line(e) or 'nested too deep'})") from None


_TOML_AT = re.compile(r"\(at line (\d+), column \d+\)")


def _repeated(text: str, e: Exception) -> str | None:
    """tomllib's refusal of a key or table given twice ("Cannot overwrite a value (at line 3, column 5)", "Cannot
    declare ('rules',) twice") as a line naming the key, or None for another error."""
    message = _one_line(e)
    at = _TOML_AT.search(message)
    if not at or not message.startswith(("Cannot overwrite a value", "Cannot declare")):
        return None
    lines = text.splitlines()
    line = int(at.group(1))
    said = lines[line - 1].strip() if 0 < line <= len(lines) else ""
    key = said.strip("[] ") if said.startswith("[") else said.partition("=")[0].strip()
    return (f"{_show(key)} is given twice (line {line}): TOML takes a key or a table once; remove one" if key else
            None)


def flatten(doc: dict, prefix: str = "") -> dict:
    """Nested tables -> {dotted key: value}; a value that is not a table (arrays included) is a leaf."""
    out = {}
    for k, v in doc.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


# -- applying -------------------------------------------------------------------------------------------------------

def apply_overrides(config, overrides: dict):
    """A new AgentConfig: `config` (left unchanged) with `overrides`, {dotted key: value}, applied. Keys are the
    agent's (`rules.uncertain_decay`, `recall_sharpness`, `memory.max_recalls`, `model`, ...); a nested dict is read
    as a table. ConfigError, one line naming the key, for an unknown key, a wrong type or a value out of range."""
    items = _items(overrides)
    if world := [k for k in items if _is_world(k)]:
        raise ConfigError(f"{world[0]} is a key of the world's config, not the agent's (apply_world_overrides, or "
                          "resolve for both)", world[0])
    try:
        return _apply_agent(config, items)
    except ConfigError as e:
        raise _with_suggestion(e, _leaves(config)) from None


def apply_world_overrides(world_config, overrides: dict):
    """A new sim.world.WorldConfig: `world_config` (left unchanged) with `overrides` applied; keys as everywhere
    else, with the `world.` prefix (`world.mass_noise_g`, `world.tank.water.density`)."""
    items = _items(overrides)
    if bad := [k for k in items if not _is_world(k)]:
        raise ConfigError(f"{bad[0]} is not a key of the world's config (its keys start with {WORLD}.)", bad[0])
    try:
        return _apply_world(world_config, items)
    except ConfigError as e:
        raise _with_suggestion(e, {f"{WORLD}.{k}": v for k, v in _leaves(world_config).items()}) from None


def resolve(overrides: dict, base: RunConfig | None = None) -> RunConfig:
    """The run's config: `base` (default: RunConfig.default(), the paper model and the world as the runner builds
    it) with `overrides` applied, agent and world keys alike. The runner's: a --config file's keys, then each --set
    in order, then --model, --ablate and --seed (a later value of a key replaces an earlier one)."""
    base = base or RunConfig.default()
    items = _items(overrides)
    agent_items = {k: v for k, v in items.items() if not _is_world(k)}
    world_items = {k: v for k, v in items.items() if _is_world(k)}
    candidates = {**_leaves(base.agent), **{f"{WORLD}.{k}": v for k, v in _leaves(base.world).items()}}
    try:
        agent = _apply_agent(base.agent, agent_items, also=(WORLD,))
    except ConfigError as e:
        raise _with_suggestion(e, candidates) from None
    try:
        world = _apply_world(base.world, world_items)
    except ConfigError as e:
        raise _with_suggestion(e, candidates) from None
    return RunConfig(agent, world)


def config_dict(config) -> dict:
    """Plain JSON-able data in the TOML file's layout: a RunConfig gives the agent's fields at the top level and the
    world's under "world"; an AgentConfig or WorldConfig (any config dataclass) its own. Tuples become lists, None
    stays None (JSON null; a file says "none"). `resolve(flatten(config_dict(c)))` gives `c` back."""
    if isinstance(config, RunConfig):
        agent = _plain(config.agent)
        assert WORLD not in agent, "AgentConfig has a field named like the world's table"
        return {**agent, WORLD: _plain(config.world)}
    if not dataclasses.is_dataclass(config) or isinstance(config, type):
        raise TypeError(f"config_dict takes a config dataclass or a RunConfig, not {type(config).__name__}")
    return _plain(config)


def first_difference(a: dict, b: dict) -> str | None:
    """The first dotted key (in a's order, then b's) whose value differs between two config dicts, else None."""
    fa, fb = flatten(a), flatten(b)
    for k in list(fa) + [k for k in fb if k not in fa]:
        if k not in fa or k not in fb or fa[k] != fb[k]:
            return k
    return None


def show(value) -> str:
    """A value as this module quotes it in a message: TOML-like, cut to a readable length, on one line."""
    return _show(value)


def check_world(world_config, objects) -> None:
    """Refuse a world the workers could not build with these objects, before anything is written: the checks
    sim.world.World and sim.water.Tank make when they build the scene (in the workers, where a failure would come
    after the run started), and the posture's joints load_icub checks. ConfigError naming the key."""
    from sim.objects import ObjectsConfig
    from sim.robot import ARM_JOINTS, RobotConfig, _joint_limits, icub_urdf_path
    from sim.water import Tank

    tank, jar = world_config.tank, objects.jar
    if tank.ball_diameter_cm > jar.inner_diameter_cm - 2 * ObjectsConfig.fit_clearance_cm:   # Tank.__init__
        raise ConfigError(f"world.tank.ball_diameter_cm: a {tank.ball_diameter_cm:g} cm ball does not fit in the "
                          f"{jar.inner_diameter_cm:g} cm jar", "world.tank.ball_diameter_cm")
    room = jar.inner_diameter_cm - tank.ball_diameter_cm - 2 * ObjectsConfig.fit_clearance_cm          # World.__init__
    for o in objects.train + objects.probe:
        if o.footprint_cm > room + 1e-9:
            raise ConfigError(f"world.tank.ball_diameter_cm: object '{o.name}' does not fit beside a "
                              f"{tank.ball_diameter_cm:g} cm ball in the jar (footprint {o.footprint_cm:.2f} cm > "
                              f"{room:.2f} cm)", "world.tank.ball_diameter_cm")
    draft = Tank.ball_draft_cm(tank)                                                                    # Tank.__init__
    if jar.water_depth_cm <= draft:
        raise ConfigError(f"world.tank: the ball (ball_diameter_cm {tank.ball_diameter_cm:g}, ball_mass_g "
                          f"{tank.ball_mass_g:g}, water.density {tank.water.density:g}) floats {draft:.2f} cm deep, "
                          f"more than the jar's {jar.water_depth_cm:g} cm of water", "world.tank")
    robot, default = world_config.robot, RobotConfig()
    if robot.home_arm != default.home_arm:                                                              # set_arm
        limits = _joint_limits(icub_urdf_path())
        for name, q in zip(ARM_JOINTS, robot.home_arm):
            lo, hi = limits[name]
            if not lo <= q <= hi:
                raise ConfigError(f"world.robot.home_arm: {name}={q:g} rad is outside [{lo:.4f}, {hi:.4f}]",
                                  "world.robot.home_arm")
    if robot.colliding_links != default.colliding_links:                                                # _rewrite
        from sim.robot import parsed_urdf
        links = {link.get("name") for link in parsed_urdf(icub_urdf_path()).findall("link")}
        if bad := [name for name in robot.colliding_links if name not in links]:
            raise ConfigError(f"world.robot.colliding_links: {_show(bad[0])} is not a link of the iCub (its arm's: "
                              f"{', '.join(sorted(n for n in links if n.startswith('r_')))[:200]}...)",
                              "world.robot.colliding_links")
    posture = world_config.robot.body_posture
    if posture != RobotConfig().body_posture:                                                           # load_icub
        limits = _joint_limits(icub_urdf_path())
        for name, q in posture:
            if name in ARM_JOINTS or name not in limits:
                raise ConfigError(f"world.robot.body_posture: {name!r} is not a movable joint of the iCub outside "
                                  "the arm", "world.robot.body_posture")
            lo, hi = limits[name]
            if not lo <= q <= hi:
                raise ConfigError(f"world.robot.body_posture: {name}={q:g} rad is outside [{lo:.4f}, {hi:.4f}]",
                                  "world.robot.body_posture")


# -- the machinery --------------------------------------------------------------------------------------------------

def _is_world(key: str) -> bool:
    return key == WORLD or key.startswith(WORLD + ".")


def _items(overrides) -> dict:
    """{dotted key: value} from a dict whose keys are dotted keys (a dict value is a table), keys checked."""
    if not isinstance(overrides, dict):
        raise ConfigError(f"overrides must be a dict of dotted keys, not a {type(overrides).__name__}")
    out = {}
    for k, v in overrides.items():
        if not isinstance(k, str) or not KEY_RE.fullmatch(k):
            raise ConfigError(f"{_show(k)} is not a key: dotted names of letters, digits and _ (e.g. "
                              "rules.uncertain_decay)")
        if isinstance(v, dict):
            for kk, vv in _items(v).items():
                out[f"{k}.{kk}"] = vv
        else:
            out[k] = v
    return out


def _apply_world(world_config, items: dict):
    if WORLD in items:
        raise ConfigError(f"{WORLD} is a table of settings, not a value ({WORLD}.<key>; {WORLD} has: "
                          f"{_names(world_config)})", WORLD)
    return _apply(copy.deepcopy(world_config), WORLD + ".", {k[len(WORLD) + 1:]: (k, v) for k, v in items.items()})


def _apply_agent(config, items: dict, also: tuple = ()):
    """`items` (agent keys) on a copy of the AgentConfig `config`. A new `model` starts from that model's named
    constructor and keeps every field `config` had changed from its own model's defaults."""
    config = copy.deepcopy(config)
    if "model" in items:
        model = _check_scalar("model", str, items["model"])
        if model != config.model:
            cls = type(config)
            try:
                fresh = cls.named(model)
            except ValueError as e:
                raise ConfigError(f"model: {_one_line(e)}", "model") from None
            defaults = _leaves(cls.named(config.model))
            changed = {k: v for k, v in _leaves(config).items() if k != "model" and v != defaults.get(k)}
            config, items = fresh, {**changed, **items}
    config = _apply(config, "", {k: (k, v) for k, v in items.items()}, also)
    _check_agent_layout(config, items)
    return config


def _check_agent_layout(config, items: dict) -> None:
    """The sheet's layout the agent's code assumes, which AgentConfig does not check itself: its events and the
    object hub sit on fixed rows (aesop_torch.agent: ROW_* and OBJECT_ROWS, rows 0..19), and the hub is the sheet's
    OBJECT_ROWS (its assembly is viewed as len(OBJECT_ROWS) rows of memory.cols)."""
    from aesop_torch import agent as agent_module
    if type(config) is not agent_module.AgentConfig:
        return
    rows = agent_module.OBJECT_ROWS
    hub, memory = config.hub, config.memory
    if memory.rows <= max(rows):
        raise ConfigError(f"memory.rows: the agent's episodes use rows 0..{max(rows)} of the sheet, got "
                          f"{memory.rows}", "memory.rows")
    if hub.rows * hub.n_neurons != len(rows) * memory.cols:
        key = next((k for k in ("hub.n_neurons", "hub.rows", "memory.cols") if k in items), "hub.n_neurons")
        raise ConfigError(f"{key}: the agent's object hub is the sheet's {len(rows)} object rows: hub.rows x "
                          f"hub.n_neurons must equal {len(rows)} x memory.cols, got {hub.rows} x {hub.n_neurons} "
                          f"for {len(rows)} x {memory.cols}", key)


def _apply(obj, prefix: str, items: dict, also: tuple = ()):
    """A copy of the dataclass `obj` with `items` ({key relative to obj: (full key, value)}) applied: parts
    recursively, then this level in one dataclasses.replace (its __post_init__ sees every change at once)."""
    fields = {f.name for f in dataclasses.fields(obj)}
    hints = _hints(type(obj))
    direct, nested = {}, {}
    for rel, (full, value) in items.items():
        head, _, rest = rel.partition(".")
        if head not in fields:
            where = f"{prefix[:-1]} has" if prefix else "the top level has"
            raise ConfigError(f"unknown key {full} ({where}: {_names(obj, also)})", full)
        current = getattr(obj, head)
        if dataclasses.is_dataclass(current):
            if not rest:
                raise ConfigError(f"{full} is a table of settings, not a value ({full}.<key>; {full} has: "
                                  f"{_names(current)})", full)
            nested.setdefault(head, {})[rest] = (full, value)
        elif rest:
            raise ConfigError(f"unknown key {full} ({prefix}{head} is a value, not a table)", full)
        else:
            direct[head] = (full, _check(full, hints[head], current, value))
    changes = {head: _apply(getattr(obj, head), f"{prefix}{head}.", sub) for head, sub in nested.items()}
    changes.update({head: v for head, (_, v) in direct.items()})
    if not changes:
        return obj
    try:
        return dataclasses.replace(obj, **changes)
    except (ValueError, TypeError) as e:   # the dataclass's own validation (__post_init__)
        message = _one_line(e)
        keys = [full for full, _ in direct.values()] or [full for sub in nested.values() for full, _ in sub.values()]
        named = [k for k in keys if re.search(rf"\b{re.escape(k.rsplit('.', 1)[-1])}\b", message)]
        key = (named or keys)[0]
        who = key if named or len(keys) == 1 else ", ".join(keys)
        # "AgentConfig.ablate: 'prior' is ..." after the key "ablate" would name it twice
        message = re.sub(rf"^\w+\.{re.escape(key.rsplit('.', 1)[-1])}:\s*", "", message)
        raise ConfigError(f"{who}: {message}", key) from None


@functools.lru_cache(maxsize=None)
def _hints(cls) -> dict:
    return typing.get_type_hints(cls)


KINDS = {bool: "true or false (bool)", int: "an integer (int)", float: "a number (float)", str: "a string (str)"}
ELEMENT_KINDS = {bool: "true/false", int: "integer", float: "number", str: "string"}


def _check(key: str, hint, current, value):
    """value as the field `key` (type hint `hint`, present value `current`) takes it, or ConfigError."""
    optional = False
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        optional = len(args) < len(typing.get_args(hint))
        if len(args) != 1:
            raise ConfigError(f"{key}: a field of type {hint} is not settable here", key)
        hint = args[0]
    if optional and (value is None or value == NONE):
        return None
    if hint is tuple or typing.get_origin(hint) is tuple:
        return _check_tuple(key, current, value, optional)
    if hint in KINDS:
        return _check_scalar(key, hint, value, optional)
    raise ConfigError(f"{key}: a field of type {hint} is not settable here", key)


def _check_scalar(key: str, kind: type, value, optional: bool = False, bounds=None):
    ok = isinstance(value, kind) and (kind in (bool, str) or not isinstance(value, bool))
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        ok = True
    rng = bounds if bounds is not None else RANGES.get(key, NON_NEGATIVE if kind is int else None)
    if kind is int and rng is not None and rng[2] is None:
        rng = (rng[0], rng[1], MAX_INT)   # what a 64-bit tensor or generator holds
    if not ok:
        raise ConfigError(f"{key} takes {KINDS[kind]}{' or none' if optional else ''}, got {_show(value)}", key)
    if kind is float:
        try:
            value = float(value)
        except OverflowError:
            value = math.inf
        if not math.isfinite(value):
            raise ConfigError(f"{key} takes a finite number, got {_show(value)}", key)
    if rng and not _in_range(value, rng):
        raise ConfigError(f"{key} takes {KINDS[kind]} {_range_text(rng)}{' or none' if optional else ''}, got "
                          f"{_show(value)}", key)
    return value


def _range_text(rng) -> str:
    lo, inclusive, hi, *below = rng
    if below and not below[0]:
        return f"from {lo} to below {hi}"
    if hi is not None:
        return f"from {lo} to {hi:,}" if hi > 10 ** 6 else f"from {lo} to {hi}"
    return f"{'>=' if inclusive else '>'} {lo}"


def _in_range(v, rng) -> bool:
    """rng: (low, low included, high or None) or, for a high bound not included, (..., high, False)."""
    lo, inclusive, hi, *hi_in = rng
    return (v >= lo if inclusive else v > lo) and (hi is None or (v <= hi if not hi_in or hi_in[0] else v < hi))


def _kind(x) -> type:
    return bool if isinstance(x, bool) else int if isinstance(x, int) else float if isinstance(x, float) else str


def _check_tuple(key: str, current, value, optional: bool = False):
    """An array for a tuple field, checked against the present value's structure: a tuple of pairs (or any
    fixed-length tuples: delta_p_band, body_posture) takes arrays of that length with those element kinds; a flat
    tuple takes elements of its kind (integers where every present element is one, else numbers, or strings; an
    empty one - ablate - takes strings). The world's flat tuples of numbers are points, colours and one value per
    arm joint: they keep their length."""
    current = tuple(current)
    if current and all(isinstance(x, tuple) for x in current):
        inner = tuple(_kind(x) for x in current[0])
        fixed = None
        desc = "an array of [" + ", ".join(ELEMENT_KINDS[k] for k in inner) + "] arrays"
    else:
        kinds = {_kind(x) for x in current}
        inner = None
        elem = (kinds.pop() if len(kinds) == 1 else float if kinds <= {int, float} else str) if kinds else str
        fixed = len(current) if key.startswith(WORLD + ".") and elem in (int, float) else None
        desc = f"an array of {fixed} {ELEMENT_KINDS[elem]}s" if fixed else f"an array of {ELEMENT_KINDS[elem]}s"
    desc += " or none" if optional else ""
    if not isinstance(value, (list, tuple)) or (fixed is not None and len(value) != fixed):
        raise ConfigError(f"{key} takes {desc}, got {_show(value)}", key)
    out = []
    for i, x in enumerate(value):
        where = f"{key}[{i}]"
        if inner is not None:
            if not isinstance(x, (list, tuple)) or len(x) != len(inner):
                raise ConfigError(f"{key} takes {desc}, got {_show(value)} ({where} is {_show(x)})", key)
            out.append(tuple(_element(f"{where}[{j}]", k, y, key, desc) for j, (k, y) in enumerate(zip(inner, x))))
        else:
            x = _element(where, elem, x, key, desc)
            if key in ELEMENT_RANGES and not _in_range(x, ELEMENT_RANGES[key]):
                raise ConfigError(f"{key} takes {desc}, each {_range_text(ELEMENT_RANGES[key])}, got {where} = "
                                  f"{_show(x)}", key)
            out.append(x)
    return tuple(out)


def _element(where: str, kind: type, x, key: str, desc: str):
    ok = isinstance(x, kind) and (kind in (bool, str) or not isinstance(x, bool))
    if kind is float and isinstance(x, int) and not isinstance(x, bool):
        ok, x = True, float(x) if abs(x) < 2 ** 1023 else math.inf
    if not ok or (kind is float and not math.isfinite(x)):
        raise ConfigError(f"{key} takes {desc}, finite numbers, got {where} = {_show(x)}", key)
    return x


def _names(obj, also: tuple = ()) -> str:
    return ", ".join([f.name for f in dataclasses.fields(obj)] + list(also))


def _leaves(obj, prefix: str = "") -> dict:
    """{dotted key: value} of every leaf field of a config dataclass."""
    out = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            out.update(_leaves(v, f"{prefix}{f.name}."))
        else:
            out[f"{prefix}{f.name}"] = v
    return out


def _with_suggestion(e: ConfigError, candidates: dict) -> ConfigError:
    """An unknown key's error with the known keys that end like it ("did you mean world.mass_noise_g?")."""
    message = str(e)
    if e.key and message.startswith("unknown key"):
        last = e.key.rsplit(".", 1)[-1]
        near = [k for k in candidates if k.rsplit(".", 1)[-1] == last and k != e.key]
        if near:
            message += f"; did you mean {' or '.join(near[:3])}?"
    return ConfigError(message, e.key)


def _plain(x):
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {f.name: _plain(getattr(x, f.name)) for f in dataclasses.fields(x)}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    return x


def _one_line(e: BaseException) -> str:
    lines = str(e).strip().splitlines()
    return lines[0] if lines else ""


def _show(v, depth: int = 0) -> str:
    """A value as TOML would write it, on one line, cut: strings quoted with escapes (no control character reaches a
    terminal), huge integers by their length, long or deep arrays elided."""
    if isinstance(v, str):
        from sim.input_files import MAX_SHOWN   # cut as every refused value is (CONTRACTS.md)
        return repr(v if len(v) <= MAX_SHOWN else v[:MAX_SHOWN - 3] + "...")
    if isinstance(v, bool):
        return "true" if v else "false"
    if v is None:
        return NONE
    if isinstance(v, int):
        return str(v) if abs(v) < 10 ** 30 else f"an integer of about {int(v.bit_length() * 0.30103) + 1} digits"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, (list, tuple)):
        if depth >= 3:
            return "[...]"
        return "[" + ", ".join(_show(x, depth + 1) for x in v[:8]) + (", ..." if len(v) > 8 else "") + "]"
    if isinstance(v, dict):
        return "a table"
    return _show(str(v))
