"""The field's statistics for the battery (issue 46): learning slopes from a conditional logit with intervals that
hold under separation, Holm's correction over tasks, the transfer gain of experienced over naive subjects as a
paired difference of expected P(correct), and the project's own rule for "learned".

- Learning slope: a logit of the first drop's correctness on trial number with an intercept per subject, the
  intercepts conditioned away (the conditional logit, as statsmodels' ConditionalLogit fits it): per subject with
  k right of n trials, P(which trials were right) = exp(b sum_right t) / sum over k-subsets S of exp(b sum_S t), the
  denominator an elementary symmetric polynomial (computed exactly by recursion). Subjects right on every trial or
  none drop out (they tell nothing about b). The slope's interval is the likelihood-ratio (profile) interval
  {b: 2 (l(b_hat) - l(b)) <= 3.84}: when every subject's wrong choices come before its right ones (separation)
  b_hat is infinite and the interval is [lo, inf), still a valid 95 % interval, where a Wald interval fails. p: the
  likelihood-ratio test of b = 0, one-sided (b > 0).
- "Learned" (the project's own rule, not a study's): trial 1 not above chance (the 95 % interval of the subjects'
  mean expected P(correct) on trial 1 reaches down to chance) and the slope's one-sided p below 0.05 after Holm's
  correction over the tasks of one condition.
- Transfer gain: per subject, experienced minus naive expected P(correct) on trial 1; subjects of the same seed are
  the same animals in both conditions (paired): the mean difference with its 95 % t interval and n.
"""

from __future__ import annotations

import math

CHI2_95 = 3.841458820694124     # chi-square with 1 degree of freedom, 0.95 quantile
Z_95 = 1.959963984540054


def _log_esp(ts: list[float], k: int, b: float) -> float:
    """log e_k(exp(b t_1), ..., exp(b t_n)): the conditional logit's denominator, by the recursion
    e_j <- e_j + x e_{j-1} in log space (stable for large |b|)."""
    e = [0.0] + [-math.inf] * k
    for t in ts:
        lx = b * t
        for j in range(k, 0, -1):
            a, c = e[j], e[j - 1] + lx
            hi = max(a, c)
            e[j] = hi + math.log1p(math.exp(min(a, c) - hi)) if hi > -math.inf else -math.inf
    return e[k]


def conditional_loglik(right: list[list[bool]], b: float) -> float:
    total = 0.0
    for r in right:
        ts = list(range(1, len(r) + 1))
        k = sum(map(bool, r))
        total += b * sum(t for t, y in zip(ts, r) if y) - _log_esp(ts, k, b)
    return total


def _informative(right):
    return [list(map(bool, r)) for r in right if 0 < sum(map(bool, r)) < len(r)]


def _separation(inf) -> int:
    """+1: every subject's wrong trials all before its right ones (the likelihood rises for ever with b); -1: all
    after; 0: neither (a finite maximum)."""
    def ordered(r, up):
        first = r.index(up)
        return all(x == up for x in r[first:])
    if all(ordered(r, True) for r in inf):
        return 1
    if all(ordered(r, False) for r in inf):
        return -1
    return 0


def _root(f, lo: float, hi: float) -> float:
    """f(lo) and f(hi) of opposite signs: bisection to 1e-9."""
    flo = f(lo)
    for _ in range(200):
        mid = (lo + hi) / 2
        fm = f(mid)
        if (fm > 0) == (flo > 0):
            lo, flo = mid, fm
        else:
            hi = mid
        if hi - lo < 1e-9:
            break
    return (lo + hi) / 2


def conditional_logit_slope(right: list[list[bool]], bound: float = 50.0) -> dict:
    """The learning slope per trial (module docstring): {"slope", "ci" (lo, hi; +-inf where unbounded), "p" (one-
    sided, slope > 0), "subjects" (informative), "n" (all), "separated"}."""
    n = len(right)
    inf = _informative(right)
    if not inf:
        return {"slope": 0.0, "ci": (-math.inf, math.inf), "p": 1.0, "subjects": 0, "n": n, "separated": 0,
                "note": "not estimable: every subject chose alike on every trial"}
    def ll(b):
        return conditional_loglik(inf, b)
    sep = _separation(inf)
    if sep:
        top = ll(sep * bound)
        b_hat = sep * math.inf
    else:
        # the log-likelihood is concave in b: its maximum by bisection on the numerical derivative
        def d(b):
            return ll(b + 1e-6) - ll(b - 1e-6)
        lo, hi = -1.0, 1.0
        while d(lo) < 0 and lo > -bound:
            lo *= 2
        while d(hi) > 0 and hi < bound:
            hi *= 2
        b_hat = _root(d, lo, hi)
        top = ll(b_hat)
    def cut(b):
        return 2 * (top - ll(b)) - CHI2_95
    centre = b_hat if math.isfinite(b_hat) else sep * bound
    lo_b = -math.inf if cut(-bound) < 0 else _root(cut, -bound, centre)
    hi_b = math.inf if cut(bound) < 0 else _root(cut, centre, bound)
    if sep > 0:
        hi_b = math.inf
    if sep < 0:
        lo_b = -math.inf
    lr = max(2 * (top - ll(0.0)), 0.0)
    p_two = math.erfc(math.sqrt(lr / 2))                  # chi-square(1) tail
    p = p_two / 2 if b_hat > 0 else 1 - p_two / 2
    return {"slope": b_hat, "ci": (lo_b, hi_b), "p": p, "subjects": len(inf), "n": n, "separated": sep, "note": ""}


def mean_interval(xs: list[float]) -> dict:
    """Mean with its 95 % t interval (scipy.stats.t), n; one value or no spread: the interval is the point."""
    from scipy.stats import t as student
    n = len(xs)
    m = sum(xs) / n
    if n < 2:
        return {"mean": m, "ci": (m, m), "n": n}
    sd = math.sqrt(sum((x - m) ** 2 for x in xs) / (n - 1))
    h = float(student.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return {"mean": m, "ci": (m - h, m + h), "n": n}


def paired_gain(treated: dict, control: dict) -> dict:
    """treated, control: {subject seed: value}. The mean paired difference over the seeds both have, its 95 % t
    interval, n, and the Wilcoxon signed-rank p (two-sided; 1 when every difference is 0)."""
    from scipy.stats import wilcoxon
    seeds = sorted(set(treated) & set(control))
    d = [treated[s] - control[s] for s in seeds]
    out = mean_interval(d) if d else {"mean": math.nan, "ci": (math.nan, math.nan), "n": 0}
    out["p"] = 1.0 if not any(abs(x) > 1e-12 for x in d) else float(wilcoxon(d).pvalue)
    return out


def holm(ps: list[float]) -> list[float]:
    """Holm-adjusted p-values (statsmodels multipletests, method "holm")."""
    from statsmodels.stats.multitest import multipletests
    return [float(x) for x in multipletests(ps, method="holm")[1]] if ps else []


def learned_tasks(trial1: dict, slopes: dict, chance: dict, alpha: float = 0.05) -> dict:
    """The project's rule (module docstring): {task: (learned, holm p)} from trial1 {task: mean_interval of the
    subjects' expected P(correct) on trial 1}, slopes {task: conditional_logit_slope}, chance {task: p}."""
    tasks = list(slopes)
    adj = dict(zip(tasks, holm([slopes[t]["p"] for t in tasks])))
    return {t: (trial1[t]["ci"][0] <= chance[t] + 1e-12 and adj[t] < alpha and slopes[t]["slope"] > 0, adj[t])
            for t in tasks}
