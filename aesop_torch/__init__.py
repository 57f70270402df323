"""aesop-torch: a brain-guided model of causal learning (Bhat & Mohan, 2020) as reusable torch modules.

The names below are imported when first asked for (PEP 562), not with the package: `from aesop_torch import Agent`
works as before, while a process that needs only a torch-free module (aesop_torch.names, aesop_torch.malloc) does
not import torch through this file."""

from __future__ import annotations

import importlib

_WHERE = {
    "Agent": "agent", "AgentConfig": "agent", "EpisodeStep": "agent",
    "EncoderConfig": "encoders", "SensoryEncoder": "encoders",
    "ActionHub": "hub", "BodyHub": "hub", "Fate": "hub", "HubConfig": "hub", "ObjectHub": "hub", "RewardCode": "hub",
    "EpisodicMemory": "memory", "MemoryConfig": "memory",
    "CausalRules": "rules", "RulesConfig": "rules", "batch_knowledge": "rules",
    "SelfOrganizingMap": "som", "SOMConfig": "som",
}
__all__ = list(_WHERE)


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
    globals()[name] = value   # asked once
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
