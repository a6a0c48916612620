"""How large an SR difference a paired comparison over n episodes can detect.

The minimum detectable difference (MDE) at 95% confidence (two-sided) and 80% power is
(z_0.975 + z_0.8) * sd_d / sqrt(n) = 2.80 * sd_d / sqrt(n), where sd_d is the standard deviation of the
per-episode paired difference. Reports state it so that "no difference shown" reads as "smaller than
this, if any" rather than as "the same"; docs/concepts/reliability.md derives it and tabulates n.
"""

from __future__ import annotations

import math
from statistics import NormalDist

ALPHA = 0.05
POWER = 0.8


def min_detectable_diff(
    n: int,
    sd_d: float | None = None,
    p_a: float | None = None,
    p_b: float | None = None,
    alpha: float = ALPHA,
    power: float = POWER,
) -> float:
    """Minimum detectable SR difference (a fraction) of a paired comparison over n episodes.

    Give sd_d, the measured std of d_i = s_B,i - s_A,i (success 0/1, averaged over seeds per episode), when
    both runs exist. Else the planning form: with SRs p_a and p_b, var(d) <= p_a(1-p_a) + p_b(1-p_b)
    (independent outcomes; positively correlated agents do better); with neither, the bound sd_d <= 1.
    """
    if n <= 0:
        raise ValueError(f"n must be positive, got {n}")
    if not 0 < alpha < 1 or not 0 < power < 1:
        raise ValueError(f"alpha and power must lie in (0, 1), got alpha={alpha}, power={power}")
    if sd_d is None:
        sd_d = 1.0 if p_a is None or p_b is None else math.sqrt(p_a * (1 - p_a) + p_b * (1 - p_b))
    z = NormalDist().inv_cdf(1 - alpha / 2) + NormalDist().inv_cdf(power)
    return z * sd_d / math.sqrt(n)


def measured_mde(d: list[float] | tuple[float, ...], p_a: float, p_b: float) -> float:
    """The MDE of a comparison from its per-episode differences d. Where they barely vary (every episode a
    tie, or one episode) their std says nothing about another sample, so the planning form at the two
    SRs takes over, and the worst case where that is 0 too (both SRs 0 or 1)."""
    n = len(d)
    if n == 0:
        raise ValueError("no paired episodes")
    if n > 1:
        m = math.fsum(d) / n
        sd = math.sqrt(math.fsum((x - m) ** 2 for x in d) / (n - 1))
        if sd > 0:
            return min_detectable_diff(n, sd_d=sd)
    planned = min_detectable_diff(n, p_a=p_a, p_b=p_b)
    return planned if planned > 0 else min_detectable_diff(n)


def mde_sentence(episodes: int, sr: float | None = None) -> str:
    """The MDE a table of `episodes` paired episodes can resolve, in % points: the bound (any two agents)
    and, given the table's mean SR, the planning value for two independent agents at that SR."""
    worst = 100 * min_detectable_diff(episodes)
    text = (
        f"with {episodes} episodes, a paired comparison detects an SR difference of {worst:.1f} points at worst "
        "(95%, 80% power)"
    )
    if sr is not None and 0 < sr < 1:
        planned = 100 * min_detectable_diff(episodes, p_a=sr, p_b=sr)
        text += f", about {planned:.1f} for two agents near {100 * sr:.0f}% SR"
    return text
