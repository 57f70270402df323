"""The agent's settings that are each in range but together give knowledge or recall that cannot work: shared by
the runner (train/runner/config_checks.py, with the world's checks) and the sweeps (train/sweeps/spec.py, whose cells
have an agent and no world)."""

from __future__ import annotations

from train.common.config import ConfigError


class Joint(Exception):
    """A refusal naming several settings (`keys`, the first the one named first) and why (`message`)."""

    def __init__(self, keys, message: str):
        super().__init__(message)
        self.keys, self.message = list(keys), message

    def refusal(self, given=()) -> ConfigError:
        """One line naming the settings, led by the first of them the run set (`given`: its overrides' keys), so that
        the runner says where it came from."""
        key = next((k for k in self.keys if any(g == k or k.startswith(g + ".") or g.startswith(k + ".")
                                                for g in given)), self.keys[0])
        return ConfigError(f"{key}: {self.message}", key)


def check_knowledge(agent) -> None:
    """The rules' strengths in the order their names give them (the paper: Elimination "drastically" reduces a
    pathway, so that it no longer retro-activates, Uncertainty "marginally", Growth strengthens), and the outcome's
    "as expected" tolerance inside its "contradicted" one; in any other order the knowledge read off the strengths
    says the reverse of what was learned (eliminated_strength 5 with dominant_strength 0.01: every eliminated
    property recalled above the causal one). A run whose context the jar does not show: refused too."""
    r = agent.rules
    chain = [("rules.eliminated_strength", r.eliminated_strength), "<=", ("retro_floor", agent.retro_floor), "<",
             ("rules.uncertain_floor", r.uncertain_floor), "<=", (None, 1.0), "<",
             ("rules.dominant_strength", r.dominant_strength)]
    said = " ".join(x if isinstance(x, str) else x[0] or "1" for x in chain)
    for i in range(0, len(chain) - 2, 2):
        (ka, a), op, (kb, b) = chain[i:i + 3]
        if not (a <= b if op == "<=" else a < b):
            name = lambda k, v: f"{k} {v:g}" if k else "1"   # noqa: E731
            raise Joint([k for k in (ka, kb) if k],
                         f"{name(ka, a)} is not {op} {name(kb, b)}: a pathway's strengths keep the order {said} (an "
                         "eliminated pathway no longer retro-activates, an undecided one does, a dominant one leads)")
    for same, contra in (("same_abs_cm3", "contradiction_abs_cm3"), ("same_rel", "contradiction_rel")):
        if getattr(r, same) > getattr(r, contra):
            raise Joint([f"rules.{same}", f"rules.{contra}"],
                         f"rules.{same} {getattr(r, same):g} is above rules.{contra} {getattr(r, contra):g}: an "
                         "outcome is contradicted only beyond what is as expected")
    if agent.encoder.context:
        raise Joint(["encoder.context"],
                     f"{list(agent.encoder.context)}: a jar run perceives no context (only a task "
                     "file's apparatus shows one), so its map would never see anything; leave it empty")


def check_sheet(agent, given) -> None:
    """The sheet's rows as the agent writes and cues them (aesop_torch.agent_config: OBJECT_ROWS, AGENT_ROW_K), which
    train.common.config checks only for its size: other cue rows take a cue of another size, and a row's k-WTA of
    another k than the neurons the agent writes there refuses the first episode stored, both mid-run."""
    from aesop_torch.agent_config import AGENT_ROW_K, OBJECT_ROWS

    hub, memory = agent.hub, agent.memory
    if tuple(memory.cue_rows) != OBJECT_ROWS:
        raise Joint(["memory.cue_rows"], f"the agent cues recall with its object hub, the sheet's rows "
                                          f"{list(OBJECT_ROWS)}, got {list(memory.cue_rows)}")
    # an object row holds the hub's assembly_size neurons, the reward's rows one unit each, an event's row its code's
    # two neurons
    want = tuple(hub.assembly_size if r in OBJECT_ROWS else k for r, k in enumerate(AGENT_ROW_K))
    if tuple(memory.row_k[:len(want)]) != want:
        r = next(r for r, (a, b) in enumerate(zip(memory.row_k, want)) if a != b)
        keys = ["hub.assembly_size", "memory.row_k"] if r in OBJECT_ROWS and "memory.row_k" not in given else \
            ["memory.row_k", "hub.assembly_size"]
        raise Joint(keys, f"row {r} of the agent's episodes holds {want[r]} active neuron(s) "
                           f"({'hub.assembly_size, on an object row' if r in OBJECT_ROWS else 'its code'}), but "
                           f"memory.row_k gives it {memory.row_k[r]}: memory.row_k must begin {list(want)}")
    if hub.word_map != "word":
        raise Joint(["hub.word_map"], f"the agent hears names on its map 'word', got {hub.word_map!r}")


def check_agent(agent, given=()) -> None:
    """Every agent check; ConfigError naming the settings involved."""
    try:
        check_knowledge(agent)
        check_sheet(agent, given)
    except Joint as e:
        raise e.refusal(given) from None
