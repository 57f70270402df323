"""aesop-torch: a brain-guided model of causal learning (Bhat & Mohan, 2020) as reusable torch modules."""

from .agent import Agent, AgentConfig, EpisodeStep
from .encoders import EncoderConfig, SensoryEncoder
from .hub import ActionHub, BodyHub, HubConfig, ObjectHub, RewardCode
from .memory import EpisodicMemory, MemoryConfig
from .rules import CausalRules, RulesConfig
from .som import SelfOrganizingMap, SOMConfig

__all__ = [
    "Agent", "AgentConfig", "EpisodeStep", "EncoderConfig", "SensoryEncoder", "ActionHub", "BodyHub", "HubConfig",
    "ObjectHub", "RewardCode", "EpisodicMemory", "MemoryConfig", "CausalRules", "RulesConfig",
    "SelfOrganizingMap", "SOMConfig",
]
