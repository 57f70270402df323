"""The paper's episode loop: perceive, recall, anticipate, observe, apply the rules, encode.

`Agent` composes the property maps, the object hub, the action and body hubs, the reward code, the episodic memory
and the rules, for B agents at once (one per presentation order). It never sees the simulator: it takes
measurements (the dict an `aesop_torch.encoders.SensoryEncoder` reads) and observed outcomes as tensors, so any
object-and-outcome source can drive it.

Two models share this loop (AgentConfig.model; docs/model.md). "paper": the rules edit the pathway strengths one
firing at a time (incremental_rules.py), compare the present with the strongest recalled episode, and the prediction
is the recall-strength-weighted average of the recalled rewards (readouts.py). "extended": the evidence-set rules
with contexts (rules.py) and the fitted readout described under Prediction below, with its physics priors.

Choices the paper leaves open, made here (where one model only, it says which):
- Weight before lifting: the expectation is formed after the object is lifted, so the felt weight is part of the
  cue, for dropped objects and probes alike (a probe is lifted, weighed and put back).
- Graded maps, read as populations. An object is stored in the hub as the bump of activity around each map's winner
  (hub.ObjectHub.allocate), and a map's activity, bottom-up or retro-activated from a recalled episode, is read
  as a population vector (SelfOrganizingMap.decode): values between units, not only at a winner's codebook vector.
- Which recalled episode the rules compare against (comparisons.py): the strongest (paper), each of them (extended).
  Every compared episode is one comparison, with DeltaProperty (the property's decoded bottom-up value against the
  value that episode retro-activates, through the pathway's strength in the comparison's context: an eliminated
  pathway retro-activates nothing, so it shows no change) and DeltaContradiction (the observed volume against that
  episode's) judged against the same past event.
- Prediction (extended; the paper model averages the recalled rewards): a recall-strength-weighted readout fitted
  within each fate on the properties the rules have not ruled out, with the task's physics priors
  (fitted_readout.py).
- Names: a teacher's words (measurement["words"], e.g. the object's name) are bound to the object's hub assembly
  one-shot like its properties, every named object with an assembly of its own; they stay out of the cue of an
  object in view (AgentConfig.names_in_cue), so naming changes no recall. `imagine` goes the other way: words, no
  object, the assembly they name retro-activates the maps and is anticipated from memory.
- Goals in words: the teacher's goal phrase ("reach the green ball") is heard through the word map and drives the
  body hub's goal state (`hear_goal`); that state, with the body's present state (the ball out of reach), cues the
  episodic memory through the body rows (`goal_recall`), and what the goal needs is read from the episodes it
  brings back (train.learning.goal_trials.needed_cm3). A phrase without the goal's words is no goal the agent knows: no recall.
  The goal words join the word map's vocabulary, not a lexicon of their own, so a goal is heard as a name is and
  bound as a word-map pattern (a separate lexicon would be a lookup table beside the network).
- Encoding: an episode is not encoded when there is nothing new to learn (the paper's episode 2): the episode it is
  most like went the same way, and the two differ in at most one property. Anything else is encoded: nothing
  recalled (the paper's episode 1), a contradiction (episode 3), or a different object that happened to end the
  same (so later objects can still be compared with it).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch
from torch import nn

from . import comparisons, fate_boundary, fitted_readout, replay
from .agent_config import (ABLATIONS, AGENT_ROW_K, MODELS, OBJECT_ROWS, ROW_BODY_END, ROW_BODY_START, ROW_DROP,
                           ROW_FATE_UNSEEN, ROW_GRASP, ROW_OBJECT, ROW_REACH, ROW_REWARD, ROW_REWARD_FINE, AgentConfig)
from .comparisons import cannot_tell
from .encoders import (FUNCTION_WORDS, GOAL_WORDS, VOCABULARY, WORD_MAP, SensoryEncoder,
                       default_map_configs, encode_words, train_property_maps, unknown_words, word_activity)
from .fitted_readout import EXTENSIVE, FEATURE_COLUMNS, as_volume, feature_columns
from .hub import ActionHub, BodyHub, ObjectHub, RewardCode, _relative
from .contextual_rules import FATE, FLOATING, SINKING, ContextualRules
from .incremental_rules import IncrementalRules
from .local_readout import local_readout, property_columns
from .memory import EpisodicMemory
from .readouts import recall_average
from .rules import DOMINANT, ELIMINATION, GROWTH, STATUS_QUO, UNCERTAINTY, CausalRules
from .som import SelfOrganizingMap

# re-exported: the names other modules import from here (the config, the sheet's layout, the readout's features)
__all__ = ["ABLATIONS", "AGENT_ROW_K", "EXTENSIVE", "FEATURE_COLUMNS", "MODELS", "OBJECT_ROWS", "ROW_BODY_END",
           "ROW_BODY_START", "ROW_DROP", "ROW_FATE_UNSEEN", "ROW_GRASP", "ROW_OBJECT", "ROW_REACH", "ROW_REWARD",
           "ROW_REWARD_FINE", "Agent", "AgentConfig", "Anticipation", "EpisodeStep", "Goal", "Imagination",
           "as_volume", "cannot_tell", "feature_columns", "BODY_ROWS", "GOAL_START", "GOAL_STATE", "NAME_SAME"]

NAME_SAME = 0.99   # name_match of an object's own name is 1 up to float rounding; one word of 6 changed gives 0.83


@dataclass
class Anticipation:
    """What the agent expects of an object before dropping it (leading dim B)."""
    expected: torch.Tensor   # (B,) the readout's prediction, NaN where nothing was recalled
    rewards: torch.Tensor    # (B, K) each recalled episode's reward (NaN where not valid), strongest first
    recall: object           # memory.Recall
    acts: torch.Tensor       # (B, P_all, U) bottom-up map activities
    present: torch.Tensor    # (B, P_all)
    values: dict | None      # map name -> (B, dim) decoded bottom-up values (None: not asked for, see anticipate_acts)
    recalled_values: dict | None   # map name -> (B, K, dim) values each recalled episode retro-activates (or None)
    fates: torch.Tensor      # (B, K) long: 0 floated, 1 sank, -1 not seen or not valid
    by_fate: torch.Tensor    # (B, 2) what it would displace if it floats, if it sinks (NaN: no episode of that fate)
    p_sink: torch.Tensor     # (B,) how likely it sinks, by the fates lived or recalled; `expected` takes the likelier


@dataclass
class Imagination:
    """What words retro-activate, with no object in view (leading dim B)."""
    known: torch.Tensor      # (B,) bool: the words name a stored object (score >= AgentConfig.imagine_floor)
    score: torch.Tensor      # (B,) how strongly the words light up the best stored assembly (1: its own name)
    runner_up: torch.Tensor  # (B,) the next best assembly's score (0 if none): how ambiguous the words are
    acts: torch.Tensor       # (B, P_all, U) the map activity the best assembly retro-activates
    values: dict             # property -> (B, dim) population-decoded values of that activity
    anticipation: "Anticipation"  # the imagined object anticipated from memory (expected NaN where not known)


@dataclass
class Goal:
    """A goal phrase as heard (leading dim B)."""
    known: torch.Tensor      # (B,) bool: the phrase names the goal (drive >= AgentConfig.goal_floor)
    drive: torch.Tensor      # (B,) the goal state's drive from the word map: the fraction of the goal's words heard
    cue: torch.Tensor        # (B, 2, cols) the body rows' cue: the present state (ball out of reach), the goal x drive


GOAL_STATE = "goal_reached"      # the body hub's state the goal words name
GOAL_START = "goal_unreachable"  # the body's state when a goal is issued: the ball out of reach (motion planner)
BODY_ROWS = (ROW_BODY_START, ROW_BODY_END)


@dataclass
class EpisodeStep:
    """What happened in one episode for each of the B agents (all tensors have leading dim B)."""
    expected: torch.Tensor   # (B,) float, NaN where nothing was recalled
    recalled: torch.Tensor   # (B,) bool
    delta_p: torch.Tensor    # (B, K, P) bool, against each recalled episode (strongest first)
    delta_c: torch.Tensor    # (B, K) bool
    fired: torch.Tensor      # (B, K, P) long, codes into rules.RULE_NAMES, per comparison
    encoded: torch.Tensor    # (B,) bool

    def rules_fired(self) -> torch.Tensor:
        """(B, P) the one rule reported per property: the most decisive that fired in any comparison,
        in the order E, G, U, S (Elimination and Growth change knowledge; Uncertainty only nudges it)."""
        rank = torch.tensor([0, 3, 2, 1])[self.fired]          # S < U < G < E
        best = rank.max(dim=1).values
        return torch.tensor([STATUS_QUO, UNCERTAINTY, GROWTH, ELIMINATION])[best]


def _check_words(phrase: str) -> None:
    """ValueError (one line) naming the words of `phrase` the agent does not know, or saying it has none."""
    unknown, tokens = unknown_words(phrase), phrase.lower().replace("_", " ").split()
    if unknown or not tokens:
        what = f"unknown word(s) {', '.join(map(repr, unknown))}" if tokens else "no words given"
        raise ValueError(f"{what}; the words I know: {' '.join(VOCABULARY + FUNCTION_WORDS)}")


class Agent(nn.Module):
    def __init__(self, config: AgentConfig | None = None, batch: int = 1, develop: bool = True):
        """develop=False skips the maps' developmental training and leaves their codebooks at zero, for an agent
        whose state is about to be loaded (`load_state_dict` brings the codebooks)."""
        super().__init__()
        self.config = config = config or AgentConfig()
        self.batch = batch
        self.encoder = SensoryEncoder(config.encoder)
        # the maps of config.encoder: the default's are the paper's four and the word map; each context property
        # (EncoderConfig.context) adds one, developed after them (their samples are drawn last, so the others'
        # maps are the same with or without context)
        if develop:
            g = torch.Generator().manual_seed(config.seed)
            self.maps = train_property_maps(config.som_samples, g, epochs=config.som_epochs, config=config.encoder)
        else:
            self.maps = nn.ModuleDict({name: SelfOrganizingMap(cfg)
                                       for name, cfg in default_map_configs(config.encoder).items()})
        # the properties the rules judge: the object's, then the context's (AgentConfig.properties)
        self.properties = config.properties
        self.hub = ObjectHub({name: m.weights.shape[0] for name, m in self.maps.items()}, config.hub, batch=batch)
        self.memory = EpisodicMemory(config.memory, batch=batch)
        self.rules = self._new_rules(batch)
        self.actions, self.body, self.reward = ActionHub(), BodyHub(), RewardCode()

    def _new_rules(self, batch: int) -> nn.Module:
        c = self.config
        if c.learning == "evidence":
            return CausalRules(c.rules, batch=batch, properties=self.properties)
        if c.learning == "contextual":
            # replay.py's lived store holds as many episodes as the memory (none when replay is ablated)
            capacity = 0 if "replay" in c.ablate else c.memory.max_episodes
            return ContextualRules(c.rules, batch=batch, properties=self.properties, retro_floor=c.retro_floor,
                                   capacity=capacity, dims={p: self.maps[p].config.dim for p in self.properties})
        return IncrementalRules(c.rules, batch=batch, properties=self.properties, retro_floor=c.retro_floor)

    def _judged(self) -> list[int]:
        """The judged properties' maps, in `properties` order: their indices into the maps (and the hub's
        pathway strengths). The default's are 0-3 (the word map, 4, is not judged); context maps come after it."""
        names = list(self.maps)
        missing = [p for p in self.properties if p not in names]
        if missing:
            raise ValueError(f"no map for the judged properties {missing} (maps: {names})")
        return [names.index(p) for p in self.properties]

    def judged_strength(self) -> torch.Tensor:
        """(B, P) the judged properties' pathway strengths (a copy; `_set_judged_strength` writes them back)."""
        return self.hub.strength[:, self._judged()]

    def _set_judged_strength(self, strength: torch.Tensor) -> None:
        self.hub.strength[:, self._judged()] = strength

    # -- perception -------------------------------------------------------------------------------------------
    def activities(self, measurement: dict) -> tuple[torch.Tensor, torch.Tensor]:
        """Bottom-up map activities (B, P_all, U) and which maps have input (B, P_all)."""
        inputs = self.encoder(measurement)
        B = next(iter(inputs.values())).shape[0]
        U = self.hub.branches.shape[3]
        acts = torch.zeros(B, len(self.maps), U)
        present = torch.zeros(B, len(self.maps), dtype=torch.bool)
        for i, (name, som) in enumerate(self.maps.items()):
            if name in inputs:
                a = word_activity(som, inputs[name]) if name == WORD_MAP else som.activity(inputs[name])
                # a name with no word the agent knows is no input (its map would still have a nearest unit)
                has = inputs[name].abs().sum(-1) > 0 if name == WORD_MAP else torch.ones(B, dtype=torch.bool)
                acts[:, i, :a.shape[-1]] = a * has[:, None]
                present[:, i] = has
        return acts, present

    def cue_present(self, present: torch.Tensor) -> torch.Tensor:
        """The maps that drive the bottom-up cue of an object in view: all with input, the word map only if
        AgentConfig.names_in_cue (names are stored with the object either way)."""
        if self.config.names_in_cue or WORD_MAP not in self.maps:
            return present
        out = present.clone()
        out[:, list(self.maps).index(WORD_MAP)] = False
        return out

    def decode(self, acts: torch.Tensor) -> dict:
        """(..., P_all, U) map activities -> {property: (..., dim) population-decoded value in the map's input}."""
        return {name: self.maps[name].decode(acts[..., i, :self.maps[name].n_units])
                for i, name in enumerate(self.maps) if name in self.properties}

    def retro_activate(self, assemblies: torch.Tensor) -> torch.Tensor:
        """(B, K, N) hub assemblies -> (B, K, P_all, U) the map activity each retro-activates at full strength
        (hub.ObjectHub.top_down before its strength gate: what the stored object looked like)."""
        return self.hub.recall_patterns(assemblies)

    def features(self, values: dict) -> torch.Tensor:
        """Decoded values -> (..., 6) readout features (FEATURE_COLUMNS): rgb, log fill, log size (cm), log mass (g)."""
        return fitted_readout.readout_features(values, self.config.encoder)

    @torch.no_grad()
    def anticipate(self, measurement: dict, decoded: bool = True) -> "Anticipation":
        """Perceive, recall and read out the expected displacement; learns nothing."""
        return self.anticipate_acts(*self.activities(measurement), decoded=decoded)

    @torch.no_grad()
    def anticipate_acts(self, acts: torch.Tensor, present: torch.Tensor, decoded: bool = True) -> "Anticipation":
        """`anticipate` from map activities (B, P_all, U) and which maps have input (B, P_all). decoded=False: the
        values (seen and recalled) are decoded only if the readout reads them, else left None: a caller that wants
        only the prediction (probes, goal trials, a population's curves) spares the decoding, a least-squares fit
        per map and agent that was a third of a population's probe readings under the paper's average readout. The
        prediction is the same bit for bit either way."""
        readout = "average" if "fit" in self.config.ablate else self.config.readout
        decoded = decoded or readout in ("prior_fit", "local_fit")
        values = self.decode(acts) if decoded else None
        p_sink = None
        if self._fates_seen():
            # the expected fate first: from the boundary fitted over every episode lived (replay's store), or, where
            # none is there, from a first recall, the cue through what decides the fate; then the cue through what
            # decides the reward in that fate recalls the episodes to read
            lived = self._lived_fates()
            if lived is not None:
                p_sink = self._fate_lived(values if values is not None else self.decode(acts), *lived)
            else:
                first = self.memory.recall(self._cue(acts, present, FATE), max_recalls=self.config.fate_recalls)
                p_sink = self._fate_vote(first) if "boundary" in self.config.ablate else self._fate_boundary(first,
                                                                                                          values)
            recall = self.memory.recall(self._cue(acts, present, (p_sink > 0.5).long()))
        else:
            recall = self.memory.recall(self._cue(acts, present))
        rewards = self.reward.decode(self._reward_row(recall.episodes))           # (B, K), NaN where not valid
        fates = self._fates(recall)
        recalled = self.decode(self.retro_activate(self._assemblies(recall.episodes))) if decoded else None
        strength = recall.strength * recall.valid
        nan = torch.full((self.batch,), float("nan"))
        by_fate, p_out = torch.stack([nan, nan], 1), nan
        if readout == "prior_fit":
            by_fate, p_out = self.readout_by_fate(self.features(values), self.features(recalled), rewards, fates,
                                                  strength)
            expected = self.expected_of(by_fate, p_out)
        elif readout == "local_fit" or p_sink is not None:
            expect = (p_sink > 0.5).long() if p_sink is not None else torch.zeros(self.batch, dtype=torch.long)
            in_fate = (fates == expect[:, None]) if p_sink is not None else strength > 0
            dominant = self._dominant(expect) if readout == "local_fit" else torch.zeros(
                self.batch, len(self.properties), dtype=torch.bool)
            expected = local_readout(values, recalled, rewards, strength, in_fate, dominant, self.properties,
                                     self.config)
            if p_sink is not None:
                p_out = p_sink
                by_fate = torch.where(torch.arange(2)[None] == expect[:, None], expected[:, None], by_fate)
        else:
            expected = recall_average(rewards, strength, self.config.recall_sharpness)
        return Anticipation(expected, rewards, recall, acts, present, values, recalled, fates, by_fate, p_out)

    def _replays(self) -> bool:
        """Whether the knowledge is consolidated by replay (contextual learning, neither rules nor replay ablated)."""
        return self._lives() and "rules" not in self.config.ablate

    def _lives(self) -> bool:
        """Whether every episode lived is kept (replay.py's store: contextual learning, replay not ablated). With
        the rules off it is still kept, for the fate's boundary (`_lived_fates`), and nothing is derived from it."""
        return self.config.learning == "contextual" and "replay" not in self.config.ablate

    def _fates_seen(self) -> bool:
        """Whether the rules keep knowledge per fate (contextual learning, contexts not ablated): then recall goes
        in two steps, the fate first."""
        return self.config.learning == "contextual" and "context" not in self.config.ablate

    def _cue(self, acts: torch.Tensor, present: torch.Tensor, context: int | torch.Tensor | None = None
             ) -> torch.Tensor:
        """The hub's bottom-up cue to the memory. Knowledge reaches recall through the pathways' strengths: the
        hub's, or those of a context of the rules (an int, or (B,) long per agent: contextual_rules.CONTEXTS). The
        "gating" ablation cuts that: all at 1."""
        if "gating" in self.config.ablate:
            strength = torch.ones_like(self.hub.strength)
        elif context is None:
            strength = None
        else:
            strength = self.hub.strength.clone()
            ctx = torch.as_tensor(context).expand(self.batch)
            known = self.rules.context_strength()[torch.arange(self.batch), ctx]
            if self.config.cue_ceiling is not None:
                known = known.clamp(max=self.config.cue_ceiling)
            strength[:, self._judged()] = known
        cue = self.hub.bottom_up(acts, self.cue_present(present), strength=strength)
        if not self.config.names_in_cue:
            # an object known only by its name (no episode of it stored) takes no part in the recall of one in view
            cue = cue * self._episode_neurons().to(cue.dtype)
        return cue

    def _fate_vote(self, recall) -> torch.Tensor:
        """(B,) how likely the object sinks: the recalled episodes' seen fates, each weighted by its recall strength
        to the power recall_sharpness (as the average weighs rewards); 0.5 where no fate was seen."""
        fates = self._fates(recall)
        sank = torch.where(fates >= 0, fates.float(), torch.full_like(fates, float("nan"), dtype=torch.float32))
        p = recall_average(sank, recall.strength * recall.valid, self.config.recall_sharpness)
        return torch.nan_to_num(p, nan=0.5)

    def _lived_fates(self) -> tuple | None:
        """(xk (B, M, D), fates (B, M)) every episode lived as replay.py keeps it (its properties' decoded values,
        in property_columns' layout, and its fate; -1 past the agent's count), when the expected fate is read from
        it: the boundary on (not ablated), the lived store kept (replay on) and some episode's fate seen in it.
        None otherwise (then a recall brings the episodes to fit: the `lived` ablation, and an agent whose
        episodes came by `remember`, which fills the memory but not the lived store)."""
        if "boundary" in self.config.ablate or "lived" in self.config.ablate or not self._lives():
            return None
        r = self.rules
        M = r.lived_values.shape[1]
        valid = torch.arange(M)[None] < r.lived_count[:, None]
        fates = torch.where(valid, r.lived_fate, torch.full_like(r.lived_fate, -1))
        if M == 0 or not (fates >= 0).any():
            return None
        xk = torch.where(valid[..., None], r.lived_values, torch.full_like(r.lived_values, float("nan")))
        return xk, fates

    def _fate_lived(self, values: dict, xk: torch.Tensor, fates: torch.Tensor) -> torch.Tensor:
        """(B,) how likely the object sinks: the boundary fitted over every episode lived (`_lived_fates`), each
        counted once, over the properties `_fate_columns` lets in. A boundary needs examples on both sides and
        around the present object; the fate's recall brought back at most fate_recalls (8) episodes most like it,
        few and on one side, and a fit over ~8 live dimensions on 8 episodes is free to put the boundary anywhere:
        the probes' fate after 24 objects was wrong in 228 of 640 (probe, order) fitted on the recalled, 128 on
        every episode lived (tuning seeds 1000-1019 x 4 orders). It also spares the fate's recall (a whole recall
        settles the network once per episode it brings back)."""
        x, cols = property_columns(values, self.properties)
        w = (fates >= 0).double()
        return fate_boundary.expected_fate(x, xk, fates, w, self._fate_columns(x, cols),
                                           self.config.fate_boundary_ridge)

    def _fate_columns(self, x: torch.Tensor, cols: list) -> torch.Tensor:
        """(B, D) bool, the columns of property_columns' layout the fate boundary is fitted over: the properties
        live for the fate (its fate pathway shows it, and the two reward contexts have not both eliminated it:
        then it matters nowhere, colour), and of those, where any is dominant in some context, only the dominant
        ones (the `causes` ablation: every live one). What decides the reward of a floater or of a sinker is what
        the robot has found to matter; a property it has found to matter nowhere yet, only undecided, adds
        dimensions the few fates can be split along by chance: colour (3) and elongation (2) beside fill, size and
        weight, with 24 episodes. Probes' fate wrong after 24 objects: 128 of 640 over every live property, 76 over
        the dominant ones (tuning seeds 1000-1019 x 4 orders; median error 4.1 % and 3.6 %)."""
        gone = self.rules.eliminated
        live = ~gone[:, FATE] & ~(gone[:, FLOATING] & gone[:, SINKING])
        if "causes" not in self.config.ablate:
            dominant = self.rules.dominant.any(1) & live
            live = torch.where(dominant.any(-1, keepdim=True), dominant, live)
        columns = torch.zeros_like(x, dtype=torch.bool)
        for i, c in enumerate(cols):
            columns[:, c] = live[:, i, None]
        return columns

    def _fate_boundary(self, recall, values: dict) -> torch.Tensor:
        """(B,) how likely the object sinks: a boundary fitted over the recalled episodes' perceived values of the
        properties live for the fate (fate_boundary.expected_fate), every recalled episode counted once (a boundary
        needs its far examples as much as its near ones: weighted by recall strength to the power fit_sharpness,
        the probes' fate was right 68 % of the time after 24 objects with the right knowledge given, counted once
        75 %; tuning seeds 1004-1009); 0.5 where no fate was seen. A property is live for the fate while its fate
        pathway shows it and the two reward contexts have not both eliminated it (then it matters nowhere: colour)."""
        fates = self._fates(recall)
        recalled = self.decode(self.retro_activate(self._assemblies(recall.episodes)))
        w = (recall.strength * recall.valid > 0).double()
        x, cols = property_columns(values, self.properties)
        xk, _ = property_columns(recalled, self.properties)
        return fate_boundary.expected_fate(x, xk, fates, w, self._fate_columns(x, cols),
                                           self.config.fate_boundary_ridge)

    def _dominant(self, fate: torch.Tensor) -> torch.Tensor:
        """(B, P) the properties dominant in each agent's expected fate (fate (B,) long: 0 floats, 1 sinks), or
        overall where the rules keep no contexts."""
        if self._fates_seen():
            return self.rules.dominant[torch.arange(self.batch), fate]
        return self.rules.state == DOMINANT

    @staticmethod
    def _assemblies(episodes: torch.Tensor) -> torch.Tensor:
        """(..., rows, cols) sheets -> (..., N) the object hub's assembly, from its rows."""
        return episodes[..., list(OBJECT_ROWS), :].flatten(-2)

    def _episode_neurons(self) -> torch.Tensor:
        """(B, N) the hub neurons of the objects of stored episodes (the memory's object rows)."""
        return self._assemblies(self.memory.patterns).any(1)

    def _reward_row(self, episodes: torch.Tensor) -> torch.Tensor:
        """(..., rows, cols) sheets -> (..., cols) the reward's 2-hot row, from its coarse (either fate's half) and
        fine rows."""
        c, f = self.reward.config.coarse, self.reward.config.fine
        row = torch.zeros_like(episodes[..., ROW_REWARD, :])
        row[..., :c] = episodes[..., ROW_REWARD, :c] | episodes[..., ROW_REWARD, c:2 * c]
        row[..., c:c + f] = episodes[..., ROW_REWARD_FINE, :f]
        return row

    def _fates(self, recall) -> torch.Tensor:
        """(B, K) long: 0 floated, 1 sank (the half of the coarse row the reward is in), -1 not seen or not valid."""
        c = self.reward.config.coarse
        row = recall.episodes[:, :, ROW_REWARD]                                  # (B, K, N)
        floated, sank = row[..., :c].any(-1), row[..., c:2 * c].any(-1)
        seen = recall.valid & (floated ^ sank) & ~recall.episodes[:, :, ROW_FATE_UNSEEN].any(-1)
        return torch.where(seen, sank.long(), torch.full_like(sank, -1, dtype=torch.long))

    def readout(self, x: torch.Tensor, xk: torch.Tensor, rewards: torch.Tensor, fates: torch.Tensor,
                weight: torch.Tensor) -> torch.Tensor:
        """fitted_readout.readout with this agent's config and rules."""
        return fitted_readout.readout(x, xk, rewards, fates, weight, self.config, self.rules)

    @staticmethod
    def expected_of(by_fate: torch.Tensor, p_sink: torch.Tensor) -> torch.Tensor:
        """fitted_readout.expected_of: the displacement of the likelier fate (NaN where neither has a fit)."""
        return fitted_readout.expected_of(by_fate, p_sink)

    def readout_by_fate(self, x: torch.Tensor, xk: torch.Tensor, rewards: torch.Tensor, fates: torch.Tensor,
                        weight: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """fitted_readout.readout_by_fate with this agent's config and rules: (B, 2) by fate, (B,) P(sinks)."""
        return fitted_readout.readout_by_fate(x, xk, rewards, fates, weight, self.config, self.rules)

    def _will_sink(self, cols: torch.Tensor, d: torch.Tensor, fates: torch.Tensor, weight: torch.Tensor,
                   steps: int = 12) -> torch.Tensor:
        """fitted_readout.will_sink with this agent's fate_ridge."""
        return fitted_readout.will_sink(cols, d, fates, weight, self.config.fate_ridge, steps)

    def name_match(self, word_acts: torch.Tensor) -> torch.Tensor:
        """(B, U_word) word map activity -> (B, max_assemblies) how well it matches the name stored with each
        object: the cosine of the activity (relative to its peak, cut at the store floor as stored) and the word
        map pattern the object's assembly retro-activates; 0 for an object stored without a name or an empty slot."""
        w = list(self.maps).index(WORD_MAP)
        word = _relative(word_acts)
        word = torch.where(word >= self.config.hub.store_floor, word, torch.zeros_like(word))   # as stored
        stored = self.retro_activate(self.hub.assemblies)[:, :, w, :word.shape[-1]]            # (B, A, U_word)
        return torch.einsum("bu,bau->ba", word, stored) / (word.norm(dim=-1, keepdim=True) *
                                                           stored.norm(dim=-1)).clamp_min(1e-12)

    def _phrases(self, words) -> list[str]:
        """A phrase, or one per agent -> B phrases; ValueError (one line) for another count or a word the agent
        does not know."""
        B = self.batch
        phrases = [words] * B if isinstance(words, str) else list(words)
        if len(phrases) != B or not all(isinstance(p, str) for p in phrases):
            raise ValueError(f"words must be a phrase or {B} phrases")
        for phrase in phrases:
            _check_words(phrase)
        return phrases

    @torch.no_grad()
    def imagine(self, words) -> Imagination:
        """Words, no object in view: the word map's activity drives the hub (bottom-up, the word pathway alone), the
        stored assembly it lights up most retro-activates the property maps (W', at full strength: what that object
        looked and felt like), and that imagined object is anticipated from memory like a seen one.

        words: a phrase, or B phrases. ValueError (one line) for a word outside the vocabulary or no word at all:
        an unknown word is not guessed at. Words that name no stored object come back with known False."""
        B = self.batch
        phrases = self._phrases(words)
        w = list(self.maps).index(WORD_MAP)
        score = self.name_match(word_activity(self.maps[WORD_MAP], encode_words(phrases)))   # (B, max_assemblies)
        top = score.topk(min(2, score.shape[1]), dim=-1)
        best = top.values[:, 0]
        runner_up = top.values[:, 1] if score.shape[1] > 1 else torch.zeros_like(best)
        known = best >= self.config.imagine_floor
        assembly = self.hub.assemblies[torch.arange(B), top.indices[:, 0]] & known[:, None]
        retro = self.retro_activate(assembly[:, None])[:, 0]                           # (B, P_all, U)
        retro[:, w] = 0.0
        seen = retro.sum(-1) > 0
        seen[:, w] = False
        a = self.anticipate_acts(retro, seen)
        a.expected = torch.where(known, a.expected, torch.full_like(a.expected, float("nan")))
        return Imagination(known, best, runner_up, retro, self.decode(retro), a)

    @torch.no_grad()
    def hear_goal(self, words) -> Goal:
        """The teacher issues a goal in words (a phrase, or B phrases). The word map hears it, and its activity a
        drives the body hub's goal state by the object hub's drive rule, d = a . W / W . W clamped to [0, 1], with
        W the word map's activity for the goal words (GOAL_WORDS, bound to the state): each word's pattern has
        unit length, so d is the fraction of the goal's words heard ("reach the green ball": 1, "reach": 1/2).
        ValueError (one line) for a word outside the vocabulary: an unknown word is not guessed at."""
        B = self.batch
        phrases = self._phrases(words)
        som = self.maps[WORD_MAP]
        heard = word_activity(som, encode_words(phrases))                                 # (B, U_word)
        bound = word_activity(som, encode_words([" ".join(GOAL_WORDS)]))[0]               # (U_word,)
        drive = ((heard @ bound) / (bound @ bound)).clamp(0.0, 1.0)
        cue = torch.stack([self.body.encode([GOAL_START] * B).float(),
                           self.body.encode([GOAL_STATE] * B).float() * drive[:, None]], 1)
        return Goal(drive >= self.config.goal_floor, drive, cue)

    @torch.no_grad()
    def goal_recall(self, goal: Goal):
        """The episodes a heard goal brings back (memory.Recall, strongest first): the stored sheets seen through a
        second view of the memory whose cue rows are the body hub's (BODY_ROWS, the cue as given). An episode that
        reached the goal holds the whole cue (strength 1), one that started from the same state and missed it half
        (the goal row unmatched); every episode the cue touches comes back (max_recalls = the episodes stored).
        Agents whose phrase names no goal recall nothing."""
        cfg = replace(self.config.memory, cue_rows=BODY_ROWS, cue_power=1.0, misses=0)
        view = type(self.memory)(replace(cfg, max_episodes=1), batch=self.batch)
        view.patterns, view.count = self.memory.patterns, self.memory.count      # the same stored sheets
        cue = goal.cue * goal.known[:, None, None].to(goal.cue.dtype)
        return view.recall(cue.flatten(1), max_recalls=max(1, int(self.memory.count.max())))

    def predict(self, measurement: dict) -> torch.Tensor:
        """Expected displaced volume (cm^3) for an object, learning frozen; NaN when nothing is recalled."""
        return self.anticipate(measurement, decoded=False).expected

    def delta_property(self, values: dict, recalled: dict, strength: torch.Tensor | None = None
                       ) -> tuple[torch.Tensor, torch.Tensor]:
        """comparisons.delta_property with this agent's config: (changed, unclear), both (B, K, P) bool."""
        return comparisons.delta_property(values, recalled, self.config, strength)

    # -- one episode ------------------------------------------------------------------------------------------
    @torch.no_grad()
    def step(self, measurement: dict, observed_cm3: torch.Tensor, goal_before: torch.Tensor,
             goal_after: torch.Tensor, learn: torch.Tensor | None = None,
             sank: torch.Tensor | None = None, perceived: tuple | None = None) -> EpisodeStep:
        """One episode for every agent: the object was lifted (measurement), dropped (observed_cm3).

        goal_before / goal_after: (B,) bool, the ball reachable before / after the drop. learn: (B,) bool, agents
        that take part (default all). sank: (B,) bool, the object came to rest on the bottom (False: it floats);
        None when not seen (its comparisons then count in the mixed context, and it is stored without a fate).
        perceived: (acts, present) as `activities(measurement)` gives them, when the caller has them already (a
        population perceives each object once: the last bits of a perception depend on its batch).
        """
        B = self.batch
        learn = torch.ones(B, dtype=torch.bool) if learn is None else learn
        observed = torch.as_tensor(observed_cm3, dtype=torch.float32).reshape(B)
        fate = torch.full((B,), -1, dtype=torch.long) if sank is None else torch.as_tensor(sank).reshape(B).long()
        a = self.anticipate_acts(*(self.activities(measurement) if perceived is None else perceived))
        recall = a.recall
        strength = self.judged_strength()     # the rules rewrite it, and the hub's pathways with it
        c = comparisons.compare(a, self.reward.stored(observed)[:, None], fate, learn, self.config, self.rules,
                                strength)
        self._set_judged_strength(strength)
        delta_p, delta_c, unclear_c, skipped = c.delta_p, c.delta_c, c.unclear_c, c.skipped
        # nothing new to learn (the paper's episode 2): the episode it is most like (compared: recalled at least
        # compare_floor strongly) went the same way and differed in at most one property. Anything else is new: nothing recalled, a contradiction, an outcome that cannot
        # tell, or a different object that happened to end the same
        same = c.compared[:, 0] & ~delta_c[:, 0] & ~unclear_c[:, 0] & (delta_p[:, 0].sum(-1) <= 1) & ~skipped[:, 0]
        encoded = learn & ~same
        count = self.hub.n_assemblies.clone()
        if encoded.any():
            self._encode(a.acts, a.present, observed, goal_before, goal_after, fate, encoded)
        self._name(a.acts, a.present, learn & (self.hub.n_assemblies == count))   # not if _encode just stored it
        if self._lives():
            # at rest: the knowledge re-derived from every pair of episodes lived (replay.py), this one's pairs new
            replay.add_episode(self.rules, a.values, self.reward.stored(observed), fate, learn, self.config)
        if self._replays():
            replay.derive(self.rules, self.config)
            self._set_judged_strength(self.rules.strength_from_knowledge())
        return EpisodeStep(a.expected, recall.any & learn, delta_p, delta_c, c.fired, encoded)

    @torch.no_grad()
    def remember(self, measurement: dict, observed_cm3: torch.Tensor, goal_before: torch.Tensor,
                 goal_after: torch.Tensor, sank: torch.Tensor | None = None, mask: torch.Tensor | None = None) -> None:
        """Store an episode as experienced, for the agents in mask (default all), with no comparison and no rule:
        to fill a memory for a capacity test, or to replay a logged life. Arguments as for `step`."""
        B = self.batch
        acts, present = self.activities(measurement)
        fate = torch.full((B,), -1, dtype=torch.long) if sank is None else torch.as_tensor(sank).reshape(B).long()
        mask = torch.ones(B, dtype=torch.bool) if mask is None else torch.as_tensor(mask).reshape(B).bool()
        self._encode(acts, present, torch.as_tensor(observed_cm3, dtype=torch.float32).reshape(B),
                     torch.as_tensor(goal_before).reshape(B), torch.as_tensor(goal_after).reshape(B), fate, mask)

    def _encode(self, acts, present, observed, goal_before, goal_after, fate, mask) -> None:
        """One-shot: the object's hub assembly (reused if the hub already knows it), then the episode sheet.

        A full hub or memory does as its config's when_full says. A new object in a full hub frees an assembly
        (ObjectHub.make_room, each assembly's uses counted as the stored episodes on it: one that no episode uses
        any more goes first), and the episodes stored with the freed assembly leave the memory: its neurons will
        code for other objects, so those episodes could never be cued right again. A full memory then lets an
        episode go (EpisodicMemory.make_room); the assembly of an object's last episode stays until the hub needs
        the room, so the object is still known (its name too) and a new episode of it reuses it. Under "refuse" a
        full hub or memory raises before anything is stored."""
        best, assembly = self.hub.match(acts, self.cue_present(present))
        known = best >= self.config.hub.match_threshold
        if known.any():
            # the same object only if no property differs from what its assembly retro-activates (DeltaProperty,
            # through the pathways as they are: a property the rules eliminated cannot tell two objects apart). The
            # hub's match alone cannot tell: a remeasured object scores 0.8-1.0 on its own assembly, two distinct
            # objects up to 0.999 (generated sets of 230, seeds 1000-1004), and distinct objects sharing an
            # assembly cannot be recalled apart
            recalled = self.decode(self.retro_activate(assembly[:, None].to(acts.dtype)))
            changed, unclear = self.delta_property(self.decode(acts), recalled, self.judged_strength()[:, None])
            known &= ~(changed | unclear)[:, 0].any(-1)
        new = mask & ~known
        if (new & (self.hub.n_assemblies >= self.hub.config.max_assemblies)).any():
            held = self._assemblies(self.memory.patterns)                          # (B, M, N) each episode's object
            # the episodes on the freed assemblies leave (a stored episode's object rows are never all empty)
            self.memory.forget((held == self.hub.make_room(new, held)[:, None]).all(-1))
        if self.memory.config.when_full == "refuse":
            self.memory.make_room(mask)   # raises if full, before the hub stores the object
        fresh = self.hub.allocate(acts, present, new)
        assembly = torch.where(new[:, None], fresh, assembly)
        B, cfg = self.batch, self.config.memory
        sheet = torch.zeros(B, cfg.rows, cfg.cols, dtype=torch.bool)
        sheet[:, ROW_BODY_START] = self.body.encode(["goal_reached" if r else "goal_unreachable"
                                                     for r in goal_before.tolist()])
        sheet[:, list(OBJECT_ROWS)] = assembly.view(B, len(OBJECT_ROWS), cfg.cols)
        for row, action in ((ROW_REACH, "reach"), (ROW_GRASP, "grasp"), (ROW_DROP, "drop")):
            sheet[:, row] = self.actions.encode([action] * B)
        code = self.reward.encode(observed)                                      # 2-hot: coarse and fine unit
        c = self.reward.config.coarse
        sank = (fate == 1)[:, None]
        sheet[:, ROW_REWARD, :c] = code[:, :c] & ~sank                            # each on a row of its own, the
        sheet[:, ROW_REWARD, c:2 * c] = code[:, :c] & sank                        # coarse one in the fate's half
        sheet[:, ROW_REWARD_FINE, :self.reward.config.fine] = code[:, c:c + self.reward.config.fine]
        sheet[:, ROW_BODY_END] = self.body.encode(["goal_reached" if r else "goal_unreachable"
                                                   for r in goal_after.tolist()])
        sheet[fate < 0, ROW_FATE_UNSEEN, :2] = True
        self.memory.store(sheet, mask)

    def _name(self, acts, present, mask) -> None:
        """A named object the hub does not know by that name gets an assembly of its own, with its name: one whose
        episode was not encoded (nothing new to learn), or was stored on the assembly of a look-alike of another
        name (`_encode` reuses an assembly the object matches, and once colour is irrelevant a blue cylinder
        matches a red one). The teacher named it, and `imagine` must find it by that name; recall is unchanged,
        since the cue of an object in view leaves names out."""
        if WORD_MAP not in self.maps:
            return
        w = list(self.maps).index(WORD_MAP)
        named = mask & present[:, w]
        if named.any():
            # a stored object it matches (the rules may have made a pathway too weak to tell them apart: a blue
            # cylinder like a red one once colour is irrelevant) is the same object only if it has the same name
            # each stored object's own match (hub.object_match, as `ObjectHub.match` reads it): the mean over an
            # assembly of the hub's activity counts neurons it shares with better-matching objects (beyond 10)
            score = self.hub.object_match(acts, self.cue_present(present))
            best, i = score.max(-1)
            same_name = self.name_match(acts[:, w, :self.maps[WORD_MAP].n_units]).gather(1, i[:, None])[:, 0]
            new = named & ((best < self.config.hub.match_threshold) | (same_name < NAME_SAME))
            if new.any():
                if (new & (self.hub.n_assemblies >= self.hub.config.max_assemblies)).any():   # as in `_encode`
                    held = self._assemblies(self.memory.patterns)
                    self.memory.forget((held == self.hub.make_room(new, held)[:, None]).all(-1))
                self.hub.allocate(acts, present, new)

    def knowledge(self, b: int = 0) -> dict:
        return self.rules.knowledge(b)

    @torch.no_grad()
    def pairwise_evidence(self, measurement: dict, observed_cm3: torch.Tensor, sank: torch.Tensor
                          ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Every pair of n episodes compared through this agent's maps, at full strength, as
        `rules.batch_knowledge` reads them: (delta_p (n, n, P), delta_c (n, n), context (n, n)), episode j against
        episode i at [i, j]. Outcomes are read through the reward code, as the memory holds them. A pair that
        cannot tell (the outcome in its dead zone, or a contradiction with a property in its dead zone) shows no
        change and no contradiction, as the agent leaves such a comparison out."""
        acts, _ = self.activities(measurement)
        observed = self.reward.stored(torch.as_tensor(observed_cm3, dtype=torch.float32))
        return comparisons.pairwise(self.decode(acts), observed, sank, self.config)

    @torch.no_grad()
    def select(self, index) -> "Agent":
        """A new Agent of batch len(index) whose agent i is a copy of this one's agent index[i] (repeats allowed).

        Lets a population branch: agents that saw the same first objects are one agent until their orders differ.
        The learned per-agent state (hub, memory, rules: every persistent buffer, all batch-first) is copied; the
        property maps are frozen after development, so they are shared, not retrained."""
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
        sizes = {name: m.weights.shape[0] for name, m in self.maps.items()}
        # the parts keep their types (a subclass, e.g. a memory with a different recall schedule, stays one)
        dev = self.hub.branches.device
        new.hub = type(self.hub)(sizes, self.config.hub, batch=1).to(dev)
        new.memory = type(self.memory)(self.config.memory, batch=1).to(dev)
        new.rules = new._new_rules(1).to(dev)
        for name in ("hub", "memory", "rules"):
            old, part = getattr(self, name), getattr(new, name)
            if hasattr(part, "batch"):
                part.batch = new.batch
            for key in old.state_dict():   # persistent buffers: exactly the batch-first learned state
                setattr(part, key, getattr(old, key)[index.to(getattr(old, key).device)])
        return new
