"""The paper's episode loop: perceive, recall, anticipate, observe, apply the rules, encode.

`Agent` composes the property maps, the object hub, the action and body hubs, the reward code, the episodic memory
and the rules, for B agents at once (one per presentation order). It never sees the simulator: it takes
measurements (the dict an `aesop_torch.encoders.SensoryEncoder` reads) and observed outcomes as tensors, so any
object-and-outcome source can drive it.

Choices the paper leaves open, made here:
- Weight before lifting: the expectation is formed after the object is lifted, so the felt weight is part of the
  cue, for dropped objects and probes alike (a probe is lifted, weighed and put back).
- Which recalled episode the rules compare against: each of them. Every recalled episode is one comparison, with
  DeltaProperty and DeltaContradiction both judged against that episode (its retro-activated properties and its
  reward): judging a property change and an outcome change against the same past event is what lets the rules
  attribute the one to the other. Comparing with the strongest recall alone lets a provisional belief (a property
  wrongly grown dominant pulls recall towards episodes that share it) hide the very episode that would refute it.
  The prediction still averages every recalled episode's reward, weighted by recall strength, as the paper says.
- Encoding: an episode is encoded when nothing was recalled (pure exploration, the paper's episode 1) or when the
  outcome contradicted the expectation (Growth or Uncertainty: "there is something new to learn"); an episode that
  went as expected is not encoded (the paper's episode 2).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from .encoders import PROPERTIES, EncoderConfig, SensoryEncoder, default_map_configs, train_property_maps
from .hub import ActionHub, BodyHub, HubConfig, ObjectHub, RewardCode
from .memory import EpisodicMemory, MemoryConfig
from .som import SelfOrganizingMap
from .rules import ELIMINATION, GROWTH, STATUS_QUO, UNCERTAINTY, CausalRules, RulesConfig, contradiction

# Rows of an episode on the 20 x 50 memory sheet: one event per row, in time order.
ROW_BODY_START, ROW_OBJECT, ROW_REACH, ROW_GRASP, ROW_DROP, ROW_REWARD, ROW_BODY_END = range(7)


@dataclass
class AgentConfig:
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    hub: HubConfig = field(default_factory=HubConfig)
    memory: MemoryConfig = field(default_factory=MemoryConfig)
    rules: RulesConfig = field(default_factory=RulesConfig)
    # the property maps are trained before the experiment on the infant's prior experience; 4000 samples cover
    # the colour cube, the four shapes and the size and mass ranges densely enough for maps of <= 64 units.
    som_samples: int = 4000
    som_epochs: int = 30
    # DeltaProperty: 1 - cosine(bottom-up activity, top-down activity) above this means the property changed.
    # Bumps one unit apart overlap with cosine ~0.6-0.8 (SOM quantisation of the same value), clearly different
    # values give ~0; 0.5 sits between.
    delta_p_threshold: float = 0.25
    # The prediction averages recalled rewards weighted by strength ** sharpness. Recall strength adds up matches
    # property by property, but the outcome needs them jointly (Archimedes: a sinker displaces its volume, a
    # floater its mass); at power 8 an episode matching every causal property (strength ~1) outweighs one matching
    # half of them (~0.5) 256 to 1, while near-equal matches still average. Measured over 300 orders of the
    # default set: median probe error 23 % after 8 episodes at power 8, 36 % at 4, 42 % at 1 (the plain average).
    prediction_sharpness: float = 8.0
    seed: int = 0

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "AgentConfig":
        parts = {"encoder": EncoderConfig, "hub": HubConfig, "memory": MemoryConfig, "rules": RulesConfig}
        return cls(**{k: parts[k](**v) if k in parts else v for k, v in d.items()})


@dataclass
class Anticipation:
    """What the agent expects of an object before dropping it (leading dim B)."""
    expected: torch.Tensor   # (B,) the prediction: rewards of all recalled episodes averaged by recall strength
    rewards: torch.Tensor    # (B, K) each recalled episode's reward (NaN where not valid), strongest first
    recall: object           # memory.Recall
    acts: torch.Tensor       # (B, P_all, U) bottom-up map activities
    winners: torch.Tensor    # (B, P_all)
    present: torch.Tensor    # (B, P_all)


@dataclass
class EpisodeStep:
    """What happened in one episode for each of the B agents (all tensors have leading dim B)."""
    expected: torch.Tensor   # (B,) float, NaN where nothing was recalled
    recalled: torch.Tensor   # (B,) bool
    delta_p: torch.Tensor    # (B, K, P) bool, against each recalled episode (strongest first)
    delta_c: torch.Tensor    # (B, K) bool
    fired: torch.Tensor      # (B, K, P) long, codes into rules.RULE_NAMES, per comparison

    def rules_fired(self) -> torch.Tensor:
        """(B, P) the one rule reported per property: the most decisive that fired in any comparison,
        in the order E, G, U, S (Elimination and Growth change knowledge; Uncertainty only nudges it)."""
        rank = torch.tensor([0, 3, 2, 1])[self.fired]          # S < U < G < E
        best = rank.max(dim=1).values
        return torch.tensor([STATUS_QUO, UNCERTAINTY, GROWTH, ELIMINATION])[best]
    encoded: torch.Tensor    # (B,) bool


class Agent(nn.Module):
    def __init__(self, config: AgentConfig | None = None, batch: int = 1, develop: bool = True):
        """develop=False skips the maps' developmental training and leaves their codebooks at zero, for an agent
        whose state is about to be loaded (`load_state_dict` brings the codebooks; the lateral spread follows)."""
        super().__init__()
        self.config = config = config or AgentConfig()
        self.batch = batch
        self.encoder = SensoryEncoder(config.encoder)
        if develop:
            g = torch.Generator().manual_seed(config.seed)
            self.maps = train_property_maps(config.som_samples, g, epochs=config.som_epochs)
        else:
            self.maps = nn.ModuleDict({name: SelfOrganizingMap(cfg) for name, cfg in default_map_configs().items()})
        self.properties = PROPERTIES
        self.hub = ObjectHub({name: m.weights.shape[0] for name, m in self.maps.items()}, config.hub, batch=batch)
        self.memory = EpisodicMemory(config.memory, batch=batch)
        self.rules = CausalRules(config.rules, batch=batch, properties=PROPERTIES)
        self.actions, self.body, self.reward = ActionHub(), BodyHub(), RewardCode()
        self.register_buffer("lateral", self._lateral(), persistent=False)
        self.register_load_state_dict_post_hook(Agent._refresh_lateral)

    @staticmethod
    def _refresh_lateral(module: "Agent", _incompatible_keys) -> None:
        module.lateral.copy_(module._lateral())

    def _lateral(self) -> torch.Tensor:
        """Lateral spread of activity within each map (a unit's graded response to every codebook vector): turns a
        retro-activated unit into the bump bottom-up perception of its value would give. (P_all, U, U)."""
        U = self.hub.W.shape[2]
        lateral = torch.zeros(len(self.maps), U, U)
        for i, m in enumerate(self.maps.values()):
            n = m.weights.shape[0]
            lateral[i, :n, :n] = m.activity(m.weights)
        return lateral

    # -- perception -------------------------------------------------------------------------------------------
    def activities(self, measurement: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Bottom-up map activities (B, P_all, U), winners (B, P_all) and which maps have input (B, P_all)."""
        inputs = self.encoder(measurement)
        B = next(iter(inputs.values())).shape[0]
        U = self.hub.W.shape[2]
        acts = torch.zeros(B, len(self.maps), U)
        winners = torch.zeros(B, len(self.maps), dtype=torch.long)
        present = torch.zeros(B, len(self.maps), dtype=torch.bool)
        for i, (name, som) in enumerate(self.maps.items()):
            if name in inputs:
                a = som.activity(inputs[name])
                acts[:, i, :a.shape[-1]] = a
                winners[:, i] = som.winner(inputs[name])
                present[:, i] = True
        return acts, winners, present

    @torch.no_grad()
    def anticipate(self, measurement: dict) -> "Anticipation":
        """Perceive and recall; learns nothing."""
        acts, winners, present = self.activities(measurement)
        recall = self.memory.recall(self.hub.bottom_up(acts, present))
        rewards = self.reward.decode(recall.episodes[:, :, ROW_REWARD])          # (B, K), NaN where not valid
        w = recall.strength ** self.config.prediction_sharpness * recall.valid
        expected = (w * torch.nan_to_num(rewards)).sum(-1) / w.sum(-1)          # NaN where nothing recalled
        nan = torch.full_like(expected, float("nan"))
        expected = torch.where(recall.any, expected, nan)
        return Anticipation(expected, rewards, recall, acts, winners, present)

    def predict(self, measurement: dict) -> torch.Tensor:
        """Expected displaced volume (cm^3) for an object, learning frozen; NaN when nothing is recalled."""
        return self.anticipate(measurement).expected

    def delta_property(self, acts: torch.Tensor, recall) -> torch.Tensor:
        """(B, K, P) bool: bottom-up activity differs from the activity each recalled episode retro-activates."""
        P, K = len(self.properties), recall.episodes.shape[1]
        out = torch.zeros(acts.shape[0], K, P, dtype=torch.bool)
        for k in range(int(recall.valid.sum(1).max())):  # recalls are sorted valid-first
            top = self.hub.top_down(recall.episodes[:, k, ROW_OBJECT].to(acts.dtype))  # (B, P_all, U)
            top = torch.einsum("bpu,puv->bpv", top, self.lateral)
            cos = nn.functional.cosine_similarity(acts[:, :P], top[:, :P], dim=-1, eps=1e-12)
            out[:, k] = (1.0 - cos) > self.config.delta_p_threshold
        return out

    # -- one episode ------------------------------------------------------------------------------------------
    @torch.no_grad()
    def step(self, measurement: dict, observed_cm3: torch.Tensor, goal_before: torch.Tensor,
             goal_after: torch.Tensor, learn: torch.Tensor | None = None) -> EpisodeStep:
        """One episode for every agent: the object was lifted (measurement), dropped (observed_cm3).

        goal_before / goal_after: (B,) bool, the ball reachable before / after the drop. learn: (B,) bool, agents
        that take part (default all).
        """
        B = self.batch
        learn = torch.ones(B, dtype=torch.bool) if learn is None else learn
        observed = torch.as_tensor(observed_cm3, dtype=torch.float32).reshape(B)
        a = self.anticipate(measurement)
        recall, acts = a.recall, a.acts
        compared = recall.valid & learn[:, None]                                   # (B, K)
        delta_p = self.delta_property(acts, recall) & compared[:, :, None]          # (B, K, P)
        delta_c = contradiction(observed[:, None], a.rewards, self.config.rules) & compared
        # every recalled episode is a comparison, strongest first; the rules' precedence makes the knowledge the
        # same whatever order the comparisons come in (see rules.py)
        strength = self.hub.strength[:, :len(self.properties)]
        fired = torch.stack([self.rules.apply(delta_p[:, k], delta_c[:, k], compared[:, k], strength=strength)
                             for k in range(compared.shape[1])], dim=1)           # (B, K, P)
        # an episode is new when nothing was recalled or it contradicts the episode it is most like
        encoded = learn & (~recall.any | delta_c[:, 0])
        if encoded.any():
            self._encode(acts, a.winners, a.present, observed, goal_before, goal_after, encoded)
        return EpisodeStep(a.expected, recall.any & learn, delta_p, delta_c, fired, encoded)

    def _encode(self, acts, winners, present, observed, goal_before, goal_after, mask) -> None:
        """One-shot: the object's hub assembly (reused if the hub already knows it), then the episode sheet."""
        best, assembly = self.hub.match(acts, present)
        new = mask & (best < self.config.hub.match_threshold)
        fresh = self.hub.allocate(winners, present, new)
        assembly = torch.where(new[:, None], fresh, assembly)
        B, cfg = self.batch, self.config.memory
        sheet = torch.zeros(B, cfg.rows, cfg.cols, dtype=torch.bool)
        sheet[:, ROW_BODY_START] = self.body.encode(["goal_reached" if r else "goal_unreachable"
                                                     for r in goal_before.tolist()])
        sheet[:, ROW_OBJECT] = assembly
        for row, action in ((ROW_REACH, "reach"), (ROW_GRASP, "grasp"), (ROW_DROP, "drop")):
            sheet[:, row] = self.actions.encode([action] * B)
        sheet[:, ROW_REWARD] = self.reward.encode(observed)
        sheet[:, ROW_BODY_END] = self.body.encode(["goal_reached" if r else "goal_unreachable"
                                                   for r in goal_after.tolist()])
        self.memory.store(sheet, mask)

    def knowledge(self, b: int = 0) -> dict:
        return self.rules.knowledge(b)

    @torch.no_grad()
    def select(self, index) -> "Agent":
        """A new Agent of batch len(index) whose agent i is a copy of this one's agent index[i] (repeats allowed).

        Lets a population branch: agents that saw the same first objects are one agent until their orders differ.
        The learned per-agent state (hub, memory, rules: every persistent buffer, all batch-first) is copied; the
        property maps and the lateral spread are frozen after development, so they are shared, not retrained."""
        index = torch.as_tensor(index)
        if index.ndim != 1 or index.numel() == 0 or index.is_floating_point() or index.dtype == torch.bool:
            raise ValueError(f"index must be a non-empty 1-d integer sequence, got shape {tuple(index.shape)} "
                             f"dtype {index.dtype}")
        if int(index.min()) < 0 or int(index.max()) >= self.batch:
            raise ValueError(f"index out of range 0..{self.batch - 1}: min {int(index.min())}, max {int(index.max())}")
        new = Agent.__new__(Agent)
        nn.Module.__init__(new)
        new.config, new.batch, new.properties = self.config, index.numel(), self.properties
        new.encoder, new.maps = self.encoder, self.maps
        new.actions, new.body, new.reward = self.actions, self.body, self.reward
        new.register_buffer("lateral", self.lateral, persistent=False)
        sizes = {name: m.weights.shape[0] for name, m in self.maps.items()}
        # the parts keep their types (a subclass, e.g. a memory with a different recall schedule, stays one)
        new.hub = type(self.hub)(sizes, self.config.hub, batch=1).to(self.hub.W.device)
        new.memory = type(self.memory)(self.config.memory, batch=1).to(self.hub.W.device)
        new.rules = type(self.rules)(self.config.rules, batch=1, properties=self.properties).to(self.hub.W.device)
        for name in ("hub", "memory", "rules"):
            old, part = getattr(self, name), getattr(new, name)
            if hasattr(part, "batch"):
                part.batch = new.batch
            for key in old.state_dict():   # persistent buffers: exactly the batch-first learned state
                setattr(part, key, getattr(old, key)[index.to(getattr(old, key).device)])
        return new
