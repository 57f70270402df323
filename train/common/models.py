"""The models a run or a sweep may name, their ablations, and whether a set fits a refusing memory: tables kept
without torch, so that the runner and the sweeps check their flags and files before torch loads (the torch-side
originals are aesop_torch.agent.MODELS and .ABLATIONS, and aesop_torch.exploration.EXPLORE; tests/test_run_cli.py
holds them equal)."""

from __future__ import annotations

MODELS = ("paper", "contextual", "extended")                          # aesop_torch.agent.MODELS, without torch
ABLATIONS = {"paper": ("rules", "gating"),                            # and .ABLATIONS
             "contextual": ("rules", "gating", "context", "fit", "boundary", "replay", "signed", "tally", "lived",
                            "causes"),
             "extended": ("rules", "gating", "prior")}
EXPLORE = ("teacher", "active")                                       # aesop_torch.exploration.EXPLORE
# what each model and each part an ablation switches off is, for --help (train/run.py builds it from these tables
# and ABLATIONS, so that a model or a part added is listed; tests/test_run_cli.py checks every one has its line)
MODEL_HELP = {
    "paper": "the paper's mechanism (rules that edit the pathway strengths one firing at a time, knowledge-gated "
             "recall, a recall-weighted average of the recalled rewards)",
    "contextual": "the paper's parts, its rules' knowledge kept per fate the robot sees (what decides the fate, what "
                  "decides the reward among floaters and among sinkers), shape split into fill and elongation, a "
                  "recall in two steps and a local fit over the recalled episodes of the expected fate",
    "extended": "evidence-set rules with floating / sinking contexts and a readout fitted with the task's physics "
                "priors",
}
ABLATION_HELP = {
    "rules": "no rule fires: the strengths stay 1, the knowledge unknown",
    "gating": "the memory's cue ignores the strengths: knowledge no longer reaches recall",
    "context": "no fates: one set of strengths judged on the reward, one recall",
    "fit": "the paper's average of the recalled rewards of the expected fate instead of the local fit",
    "prior": "the readout's fit without its physics priors",
    "boundary": "the expected fate from the recall-weighted vote of the recalled fates instead of a boundary fitted "
                "over them",
    "replay": "the sequential rules, judging each comparison once as it comes, instead of the knowledge re-derived "
              "from every pair of episodes lived after each episode",
    "signed": "replay without signed consistency (Growth on a property whose change had the outcome's sign in every "
              "clear contradicted pair)",
    "lived": "the expected fate's boundary fitted over the episodes a recall through the fate's knowledge brings "
             "back (at most fate_recalls) instead of over every episode lived",
    "causes": "the expected fate's boundary fitted over every property live for the fate instead of only those "
              "dominant in some context",
    "tally": "replay's Elimination on any clean pair whose outcome held, instead of only where such pairs are at "
             "least elim_share of the property's clean pairs (held and moved)",
}


def check_capacity(agent, n_train: int, setting=lambda key, value: f"--set {key}={value}") -> str | None:
    """Why a run of n_train episodes cannot end with this AgentConfig, in one line, or None. A memory or hub whose
    when_full is `refuse` stops the run at its first episode past capacity, maybe hours in: refused before anything
    is written instead. The hub counts the train objects: probes are predicted on copies and the goal trials run on
    a copy with room for theirs (train/learning/goal_trials.py roomy_copy). setting(key, value) spells a fix (a
    sweep file's differs from the runner's --set)."""
    full = []   # (part, its size's key, the size) of each part that would refuse
    for part, key in (("memory", "max_episodes"), ("hub", "max_assemblies")):
        c = getattr(agent, part)
        if c.when_full == "refuse" and n_train > getattr(c, key):
            full.append((part, key, getattr(c, key)))
    if not full:
        return None
    sizes = ", ".join(f"{part}.{key} = {size} and {part}.when_full = refuse" for part, key, size in full)
    forget = " ".join(setting(f"{part}.when_full", "forget_oldest") for part, _, _ in full)
    grow = " ".join(setting(f"{part}.{key}", n_train) for part, key, _ in full)
    return (f"{n_train} train objects but {sizes}: the run would stop at episode "
            f"{min(size for _, _, size in full) + 1}; {forget} (or forget_weakest), or {grow}")
