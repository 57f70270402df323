"""Checkpoints that are atomic, checksummed and checked for structure before anything trusts them.

Writing: the file is serialized in memory, written to a temporary file beside the target, fsynced, then renamed over
it, so a run killed (or out of disk space) mid-write leaves the previous checkpoint intact.

Layout (CONTRACTS.md "Checkpoint"): one `torch.save` dict {"format", "version", "sha256", "run", "experiment"}.
Everything in it is plain tensors, dicts, lists, strings and numbers, so `torch.load(path, weights_only=True)` reads
it without executing pickled code. "sha256" is the digest of a canonical encoding of "run" and "experiment" (see
`digest`): a flipped byte that torch.load still decodes changes the content and so the digest. `load` refuses, with
a one-line `CheckpointError`, a file that is too large, unreadable, foreign, damaged or of the wrong structure.
"""

from __future__ import annotations

import hashlib
import io
import os
import struct
from pathlib import Path

from sim.output_files import write_atomic
from train.learning.checkpoint_checks import finite, measurement_ok, state_problem

FORMAT = "aesop-torch checkpoint"
VERSION = 2
# 64 detailed orders of 8 objects is ~6 MB; a file far beyond any real checkpoint is refused before it is read
MAX_BYTES = 256 * 1024 * 1024
RUN_KEYS = {"objects": dict, "seed": int, "physics": str, "orders_arg": str, "model": str, "ablate": list}
EXPERIMENT_KEYS = {"train_names": list, "probe_names": list, "orders": list, "seed": int, "physics": str,
                   "config": dict, "t": int, "records": list, "outcomes": dict, "probes": dict, "agent": dict}
OUTCOME_KEYS = {"measurement", "observed_cm3", "archimedes_cm3", "goal_before", "goal_after", "sank"}
OUTCOME_OPTIONAL = {"true"}   # the file's values, kept for the logs


class CheckpointError(ValueError):
    """A checkpoint that must not be used; the message is one line saying why."""


# -- writing -----------------------------------------------------------------------------------------------------

def _write_bytes(f, data: bytes) -> None:
    f.write(data)


def _write_atomic(path: str | os.PathLike, data: bytes) -> None:
    """sim.output_files.write_atomic, its temporary file `<name>.<random>.tmp` (train/runner/out_dir.py knows a killed
    write's leftovers by it), through _write_bytes (tests stand a full disk in its place)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, data, hidden=False, write=lambda f, d: _write_bytes(f, d))


def save_atomic(state: dict, path: str | os.PathLike) -> None:
    """state: {"run": ..., "experiment": ...}; written with its format tag and checksum."""
    import torch

    buf = io.BytesIO()   # serialized in memory: a full disk shows up as a plain OSError from the write below
    torch.save({"format": FORMAT, "version": VERSION, "sha256": digest(state), **state}, buf)
    _write_atomic(path, buf.getvalue())


def write_text_atomic(text: str, path: str | os.PathLike) -> None:
    _write_atomic(path, text.encode())


# -- the checksum ------------------------------------------------------------------------------------------------

def digest(obj) -> str:
    """sha256 of a canonical encoding of plain data (dicts by sorted key, lists, tuples, str, int, float, bool,
    None, bytes, tensors by dtype, shape and bytes): equal content, equal digest, whatever the pickling."""
    h = hashlib.sha256()
    _feed(h, obj)
    return h.hexdigest()


def _feed(h, x) -> None:
    import torch

    if x is None or isinstance(x, bool):
        h.update(b"N" if x is None else (b"T" if x else b"F"))
    elif isinstance(x, int):
        s = str(x).encode()
        h.update(b"i%d:" % len(s) + s)
    elif isinstance(x, float):
        h.update(b"f" + struct.pack("<d", x))
    elif isinstance(x, str):
        s = x.encode("utf-8", "surrogatepass")
        h.update(b"s%d:" % len(s) + s)
    elif isinstance(x, bytes):
        h.update(b"b%d:" % len(x) + x)
    elif isinstance(x, (list, tuple)):
        h.update(b"%s%d:" % (b"l" if isinstance(x, list) else b"t", len(x)))
        for v in x:
            _feed(h, v)
    elif isinstance(x, dict):
        h.update(b"d%d:" % len(x))
        for k in sorted(x, key=lambda k: (type(k).__name__, str(k))):
            _feed(h, k)
            _feed(h, x[k])
    elif isinstance(x, torch.Tensor):
        t = x.detach().cpu().contiguous()
        h.update(f"T{t.dtype}{tuple(t.shape)}:".encode())
        h.update(t.view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    else:
        raise TypeError(f"cannot checksum a {type(x).__name__}")


# -- reading -----------------------------------------------------------------------------------------------------

def load(path: str | os.PathLike) -> dict:
    """{"run", "experiment"} of a checkpoint written by `save_atomic`, verified (size, format, checksum, structure).
    CheckpointError (one line) otherwise; nothing is written."""
    import torch

    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as e:
        raise CheckpointError(f"cannot read {path}: {e.strerror}") from None
    if not path.is_file():
        raise CheckpointError(f"{path} is not a regular file")
    if size > MAX_BYTES:
        raise CheckpointError(f"{path} is {size:,} bytes, larger than any checkpoint ({MAX_BYTES:,})")
    try:
        # mmap: the pickle (the tensors' headers) is read, their bytes stay on disk until something touches them
        raw = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
    except Exception as e:  # noqa: BLE001  a damaged or foreign file can fail in many ways; each is one line
        raise CheckpointError(f"{path} is not a readable checkpoint (damaged or foreign: {type(e).__name__})"
                              ) from None
    if isinstance(raw, dict) and set(raw) == {"run", "experiment"}:
        raise CheckpointError(f"{path} is a checkpoint of an older version, without a checksum: remake it, or "
                              f"convert it if you trust it (train.learning.checkpoint.upgrade)")
    if not isinstance(raw, dict) or raw.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not an aesop-torch checkpoint (no format tag {FORMAT!r})")
    if raw.get("version") != VERSION:
        raise CheckpointError(f"{path}: checkpoint version {raw.get('version')!r}, this code reads {VERSION}")
    extra = set(raw) - {"format", "version", "sha256", "run", "experiment"}
    if extra or not {"run", "experiment"} <= set(raw):
        raise CheckpointError(f"{path}: unexpected top-level keys {sorted(map(str, set(raw)))}")
    state = {"run": raw["run"], "experiment": raw["experiment"]}
    if problem := tensor_problem(state, size):   # before the checksum: digest() copies every tensor it reads
        raise CheckpointError(f"{path}: wrong structure: {problem}")
    try:
        ok = raw.get("sha256") == digest(state)
    except (TypeError, RecursionError):
        ok = False
    if not ok:
        raise CheckpointError(f"{path}: checksum mismatch, the file is damaged")
    _from_before_models(state)
    problem = structure_problem(state, size)
    if problem:
        raise CheckpointError(f"{path}: wrong structure: {problem}")
    if problem := state_problem(state["experiment"], state["run"]):
        raise CheckpointError(f"{path}: out of range: {problem}")
    return _in_memory(state)


def _from_before_models(state: dict) -> None:
    """A checkpoint written before there were two models holds the extended model (its rules and readout were the
    only ones): name it so, as a checkpoint of today would."""
    run, e = state["run"], state["experiment"]
    if isinstance(run, dict) and isinstance(e, dict) and isinstance(e.get("config"), dict) \
            and "model" not in run and "ablate" not in run and "model" not in e["config"]:
        run["model"], run["ablate"] = "extended", []
        e["config"] = {**e["config"], "model": "extended", "ablate": [], "compare_with": None}


def upgrade(path: str | os.PathLike) -> None:
    """Rewrite in place a checkpoint written before checksums ({"run", "experiment"} only) in today's format, after
    the structure check. Its content cannot be verified: use it on files you trust (e.g. a shipped default)."""
    import torch

    raw = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
    if not isinstance(raw, dict) or set(raw) != {"run", "experiment"}:
        raise CheckpointError(f"{path} is not a checkpoint of the older version")
    size = Path(path).stat().st_size
    if problem := tensor_problem(raw, size) or structure_problem(raw, size):
        raise CheckpointError(f"{path}: wrong structure: {problem}")
    save_atomic(_in_memory(raw), path)


def _typed(d: dict, spec: dict, where: str) -> str | None:
    if set(d) != set(spec):
        missing, extra = sorted(set(spec) - set(d)), sorted(map(str, set(d) - set(spec)))
        return f"{where} keys: missing {missing}, unexpected {extra}"
    for k, kind in spec.items():
        if not isinstance(d[k], kind) or (kind is int and isinstance(d[k], bool)):
            return f"{where}[{k!r}] is a {type(d[k]).__name__}, not a {kind.__name__}"
    return None


# what an agent's state is made of (aesop_torch: float32 values, int64 counts, bool patterns); anything else
# (complex, quantized, float64 ...) is no tensor this code wrote
TENSOR_DTYPES = ("float32", "int64", "bool")


def tensor_problem(state, budget: int) -> str | None:
    """What is wrong with the tensors anywhere in `state`, read from their headers only (nothing touches their
    bytes): each must be dense (strided, no sparse layout, no conjugate or negative bit), of a TENSOR_DTYPES dtype,
    with non-negative strides and offset, and hold its elements in its own stored bytes (an expanded tensor, a
    stride of 0 over a storage too small for its shape, would ask digest() for its full size); together their
    elements are at most `budget` bytes (the file's size: the bytes are in the file). None when all is well."""
    import torch

    total, stack = 0, [state]
    while stack:
        x = stack.pop()
        if isinstance(x, dict):
            stack.extend(x.keys())
            stack.extend(x.values())
        elif isinstance(x, (list, tuple)):
            stack.extend(x)
        elif isinstance(x, torch.Tensor):
            if x.layout != torch.strided or x.is_sparse or x.is_quantized or x.is_nested:
                return f"a {x.layout} tensor (only dense tensors are stored)"
            if str(x.dtype).removeprefix("torch.") not in TENSOR_DTYPES:
                return f"a tensor of {x.dtype} (stored: {', '.join(TENSOR_DTYPES)})"
            if x.is_conj() or x.is_neg() or x.device.type != "cpu":
                return "a tensor with a conjugate or negative view, or off the cpu"
            size, n = x.element_size(), x.numel()
            if any(s < 0 for s in x.stride()) or x.storage_offset() < 0:
                return f"a tensor of shape {tuple(x.shape)} with a negative stride or offset"
            span = 1 + sum((d - 1) * s for d, s in zip(x.shape, x.stride())) if n else 0
            stored = x.untyped_storage().nbytes()
            if n * size > stored or (x.storage_offset() + span) * size > stored:
                return (f"a tensor of shape {tuple(x.shape)} (strides {tuple(x.stride())}) over {stored:,} stored "
                        f"bytes: its elements are not all stored")
            total += n * size
            if total > budget:
                return f"tensors of more than {budget:,} bytes in a file of {budget:,}"
    return None


def _in_memory(state):
    """state with every tensor copied off the file's memory map (each already checked by tensor_problem)."""
    import torch

    if isinstance(state, dict):
        return {k: _in_memory(v) for k, v in state.items()}
    if isinstance(state, list):
        return [_in_memory(v) for v in state]
    if isinstance(state, tuple):
        return tuple(_in_memory(v) for v in state)
    return state.clone() if isinstance(state, torch.Tensor) else state


def structure_problem(state: dict, budget: int = MAX_BYTES) -> str | None:
    """What is wrong with a checkpoint's content (the first problem found), or None. Checks every key and type,
    that orders are permutations, records and outcomes fit the episodes done, and that the agents' tensors have
    exactly the names, shapes and dtypes of agents built from the stored config, whose buffers must fit in `budget`
    bytes (the file's size)."""
    if not isinstance(state.get("run"), dict) or not isinstance(state.get("experiment"), dict):
        return "'run' and 'experiment' must be dicts"
    if p := _typed(state["run"], RUN_KEYS, "run"):
        return p
    e = state["experiment"]
    if p := _typed(e, EXPERIMENT_KEYS, "experiment"):
        return p
    names, probes = e["train_names"], e["probe_names"]
    if not names or not all(isinstance(n, str) for n in names + probes) or len(set(names + probes)) != len(
            names + probes):
        return "object names must be distinct strings, at least one train object"
    n = len(names)
    if not e["orders"] or not all(isinstance(o, list) and sorted(o) == list(range(n)) for o in e["orders"]):
        return f"every order must be a permutation of the {n} train objects"
    if e["physics"] not in ("cached", "per-episode") or not 0 <= e["seed"] < 2 ** 63 or not 0 <= e["t"] <= n:
        return "physics, seed or episode count out of range"
    if (e["physics"], e["seed"]) != (state["run"]["physics"], state["run"]["seed"]):
        return "run and experiment disagree on physics or seed"
    config = e["config"]
    if (config.get("model"), list(config.get("ablate", ()))) != (state["run"]["model"], state["run"]["ablate"]):
        return "run and experiment disagree on the model or its ablations"
    if len(e["records"]) != len(e["orders"]) or any(not isinstance(r, list) or len(r) != e["t"] or
                                                    not all(isinstance(x, dict) for x in r) for r in e["records"]):
        return f"records must hold {e['t']} episode(s) for each of the {len(e['orders'])} orders"
    for name, o in list(e["outcomes"].items()):
        keys_ok = isinstance(o, dict) and OUTCOME_KEYS <= set(o) <= OUTCOME_KEYS | OUTCOME_OPTIONAL
        if name not in names or not keys_ok or not isinstance(o["sank"], bool) or not measurement_ok(
                o["measurement"]) or not (finite(o["observed_cm3"]) and finite(o["archimedes_cm3"])):
            return f"outcome of {name!r} is malformed"
    for name, pr in list(e["probes"].items()):
        if name not in probes or not isinstance(pr, dict) or set(pr) != {"measurement", "archimedes_cm3"} \
                or not measurement_ok(pr["measurement"]) or not finite(pr["archimedes_cm3"]):
            return f"probe {name!r} is malformed"
    if e["physics"] == "cached" and e["t"] > 0:
        missing = {names[o[i]] for o in e["orders"] for i in range(e["t"])} - set(e["outcomes"])
        if missing:
            return f"no outcome for {sorted(missing)[0]!r}, which was already dropped"
    return _agent_problem(e, budget)


def _agent_problem(e: dict, budget: int) -> str | None:
    import torch

    from aesop_torch.agent import Agent, AgentConfig
    from train.common.config import ConfigError, apply_overrides
    try:
        # the config's own validation (types, ranges, each dataclass's __post_init__), as for --config and --set
        config = apply_overrides(AgentConfig.named(e["config"].get("model")), e["config"])
    except ConfigError as err:
        return f"config: {err}"
    except Exception as err:  # noqa: BLE001  a foreign config can fail in many ways
        return f"config is not an agent's config ({type(err).__name__})"
    try:
        # the agents as train.learning.experiment.Experiment builds them (its __post_init__: seed, buffers sized to the train
        # objects), without importing it (it imports this module)
        config.seed = e["seed"]
        config.memory.max_episodes = min(config.memory.max_episodes, len(e["train_names"]))
        config.hub.max_assemblies = min(config.hub.max_assemblies, len(e["train_names"]))
        # two of its buffers (memory.patterns, hub.assemblies: one byte an element) already need this much; the
        # stored ones, the same shapes, fit in the file (tensor_problem): a config asking for more is refused here,
        # before agents that large are built (the meta device would cost nothing but takes seconds to set up)
        need = len(e["orders"]) * (config.memory.max_episodes * config.memory.rows * config.memory.cols
                                   + config.hub.max_assemblies * config.hub.n_neurons)
        if need > budget:
            return f"config asks for agents of more than {need:,} bytes, the file has {budget:,}"
        like = Agent(config, batch=len(e["orders"]), develop=False).state_dict()
    except Exception as err:  # noqa: BLE001  a foreign config can fail in many ways
        return f"config does not build an agent ({type(err).__name__})"
    got = e["agent"]
    if set(got) != set(like):
        missing, extra = sorted(set(like) - set(got)), sorted(map(str, set(got) - set(like)))
        return (f"agent state: missing {missing[:3]}, unexpected {extra[:3]} (written by another version of "
                "aesop-torch? remake it with train/run.py)")
    for k, ref in like.items():
        v = got[k]
        if not isinstance(v, torch.Tensor) or v.shape != ref.shape or v.dtype != ref.dtype:
            what = f"{tuple(v.shape)} {v.dtype}" if isinstance(v, torch.Tensor) else type(v).__name__
            return f"agent state {k!r}: {what}, expected {tuple(ref.shape)} {ref.dtype}"
        if v.is_floating_point() and not torch.isfinite(v).all():
            return f"agent state {k!r} holds non-finite values"
    return None
