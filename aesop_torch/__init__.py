"""aesop-torch: a brain-guided model of causal learning (Bhat & Mohan, 2020) as reusable torch modules."""

from .agent import Agent, AgentConfig, EpisodeStep
from .encoders import EncoderConfig, SensoryEncoder
from .hub import ActionHub, BodyHub, Fate, HubConfig, ObjectHub, RewardCode
from .memory import EpisodicMemory, MemoryConfig
from .rules import CausalRules, RulesConfig, batch_knowledge
from .som import SelfOrganizingMap, SOMConfig

__all__ = [
    "Agent", "AgentConfig", "EpisodeStep", "EncoderConfig", "SensoryEncoder", "ActionHub", "BodyHub", "Fate",
    "HubConfig", "ObjectHub", "RewardCode", "EpisodicMemory", "MemoryConfig", "CausalRules", "RulesConfig",
    "batch_knowledge", "SelfOrganizingMap", "SOMConfig",
]
