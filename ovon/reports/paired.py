"""Paired comparison of evaluation runs on the same episodes.

Every method in a table runs the same episodes, so the honest question is "on these episodes, how much
better is B than A?": a paired difference per episode, a bootstrap confidence interval that resamples
episodes (all seeds of an episode move together, since they share its difficulty), and an exact sign test
on the episodes where the two disagree (McNemar's exact test with one seed). Unpaired mean +- std over
seeds, the older rule, ignores that pairing and needs far larger gaps to call a difference.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.stats import binomtest

from ovon.evaluate.results import selected_records
from ovon.reports.compare import load_meta, load_protocol
from ovon.reports.power import measured_mde

METRICS = ("sr", "spl")
ALL = "(all splits)"  # the pooled row: parentheses cannot be in a split name


@dataclass(frozen=True)
class PairedStat:
    """B - A for one metric over paired episodes, in the metric's own unit (SR and SPL as fractions)."""

    metric: str
    a: float
    b: float
    diff: float
    ci_low: float
    ci_high: float

    @property
    def verdict(self) -> str:
        if self.ci_low > 0:
            return "B better"
        if self.ci_high < 0:
            return "A better"
        return "no difference shown"


@dataclass(frozen=True)
class SignTest:
    """Episodes (mean success over seeds) where B beats A and where A beats B; ties are left out."""

    b_wins: int
    a_wins: int
    p_value: float


@dataclass(frozen=True)
class PairedResult:
    split: str
    episodes: int
    seeds: int
    stats: tuple[PairedStat, ...]
    sign: SignTest
    mde: float  # the SR difference (a fraction) these episodes detect at 95% / 80% power (`ovon.reports.power`)


def _episode(r: dict) -> tuple[str, str, str]:
    return (r["split"], r["scene"], str(r["episode_id"]))


def _value(r: dict, metric: str) -> float:
    return float(r["success"]) if metric == "sr" else float(r[metric])


def pair_records(a: list[dict], b: list[dict], name_a: str, name_b: str) -> dict[tuple, tuple[dict, dict]]:
    """(split, seed, scene, episode id) -> (record of A, record of B); refuses runs of different episodes."""
    key = lambda r: (r["split"], int(r["seed"]), r["scene"], str(r["episode_id"]))  # noqa: E731
    ka, kb = {key(r): r for r in a}, {key(r): r for r in b}
    only_a, only_b = ka.keys() - kb.keys(), kb.keys() - ka.keys()
    if only_a or only_b:
        example = sorted(only_a or only_b)[0]
        raise ValueError(
            f"{name_a} and {name_b} ran different episodes ({len(only_a)} only in {name_a}, {len(only_b)} only in "
            f"{name_b}, e.g. split {example[0]} seed {example[1]} episode {example[3]} of {example[2]}); fix: "
            "compare runs of the same dataset, splits, --episodes / --subset and --seeds"
        )
    if not ka:
        raise ValueError(f"{name_a} and {name_b} hold no episodes; fix: compare finished `ovon evaluate` runs")
    return {k: (ka[k], kb[k]) for k in sorted(ka)}


def compare_pairs(
    pairs: dict[tuple, tuple[dict, dict]], resamples: int = 10_000, seed: int = 0, level: float = 0.95
) -> list[PairedResult]:
    """Per split and over all splits. The bootstrap is seeded, so the same runs give the same intervals."""
    groups: dict[str, dict[tuple, list[tuple[dict, dict]]]] = defaultdict(lambda: defaultdict(list))
    for (split, _seed, scene, eid), pair in pairs.items():
        groups[split][(split, scene, eid)].append(pair)
        groups[ALL][(split, scene, eid)].append(pair)
    out = []
    for split in [*sorted(s for s in groups if s != ALL), ALL]:
        episodes = list(groups[split].values())
        rng = np.random.default_rng(seed)
        picks = rng.integers(0, len(episodes), size=(resamples, len(episodes)))
        stats = []
        for metric in METRICS:
            # per episode: mean over its seeds of A's and B's value (every episode has the same seeds)
            va = np.array([math.fsum(_value(a, metric) for a, _ in eps) / len(eps) for eps in episodes])
            vb = np.array([math.fsum(_value(b, metric) for _, b in eps) / len(eps) for eps in episodes])
            d = vb - va
            boot = d[picks].mean(axis=1)
            lo, hi = np.quantile(boot, [(1 - level) / 2, (1 + level) / 2])
            stats.append(PairedStat(metric, float(va.mean()), float(vb.mean()), float(d.mean()), float(lo), float(hi)))
            if metric == "sr":
                b_wins, a_wins = int((d > 0).sum()), int((d < 0).sum())
                p = binomtest(b_wins, b_wins + a_wins, 0.5).pvalue if b_wins + a_wins else 1.0
                sign = SignTest(b_wins, a_wins, float(p))
                mde = measured_mde(d.tolist(), float(va.mean()), float(vb.mean()))
        out.append(PairedResult(split, len(episodes), len(episodes[0]) if episodes else 0, tuple(stats), sign, mde))
    return out


def compare_runs(run_dirs: list[str | Path], resamples: int = 10_000) -> dict:
    """The first run is the baseline A; each other run is B against it. JSON-ready."""
    dirs = [Path(d) for d in run_dirs]
    if len(dirs) < 2:
        raise ValueError(f"compare needs at least two run folders, got {len(dirs)}; fix: ovon compare RUN_A RUN_B")
    for d in dirs:
        if not (d / "episodes.jsonl").is_file():
            raise FileNotFoundError(f"{d} is not a run folder (no episodes.jsonl); fix: run `ovon evaluate --out {d}`")
    names = [str(load_meta(d).get("name") or d.name) for d in dirs]
    prints = [load_protocol(d).get("fingerprint") for d in dirs]
    base = selected_records(dirs[0])
    comparisons = []
    for d, name, fp in zip(dirs[1:], names[1:], prints[1:]):
        results = compare_pairs(pair_records(base, selected_records(d), names[0], name), resamples)
        comparisons.append(
            {
                "a": names[0],
                "b": name,
                # the same episodes under other rules (noise, camera, steps) is a comparison of settings too
                "same_protocol": None if fp is None or prints[0] is None else fp == prints[0],
                "splits": [
                    {
                        **{k: v for k, v in asdict(r).items() if k != "stats"},
                        "stats": [{**asdict(s), "verdict": s.verdict} for s in r.stats],
                        "verdict": verdict_text(r.stats[0].verdict, r.mde),
                    }
                    for r in results
                ],
            }
        )
    return {"baseline": names[0], "resamples": resamples, "level": 0.95, "comparisons": comparisons}


def verdict_text(verdict: str, mde: float) -> str:
    """The SR verdict as tables print it: "no difference shown" names the difference it could have shown."""
    return f"{verdict} (MDE {100 * mde:.1f} pts)" if verdict == "no difference shown" else verdict


def paired_table(result: dict) -> str:
    """Markdown: one row per (B, split), differences in % points with their 95% interval."""
    lines = [
        f"Paired differences B - A against A = {result['baseline']}, in % points; 95% bootstrap interval over "
        f"episodes ({result['resamples']} resamples); sign test on episodes where SR differs; MDE: the smallest "
        "SR difference these episodes detect (paired, 95%, 80% power, from the measured spread of the "
        "per-episode difference).",
        "",
        "| B | split | episodes x seeds | SR A | SR B | dSR [95% CI] | SPL A | SPL B | dSPL [95% CI] | B / A wins "
        "| p | MDE SR | verdict (SR) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    pct = lambda x: f"{100 * x:.1f}"  # noqa: E731
    for comp in result["comparisons"]:
        if comp.get("same_protocol") is False:
            lines.insert(
                1,
                f"{comp['b']} ran under another protocol than {comp['a']} (summary.json `protocol`): "
                "its difference mixes the agent with the settings.",
            )
        for s in comp["splits"]:
            sr, spl = s["stats"]
            sign = s["sign"]
            lines.append(
                f"| {comp['b']} | {s['split']} | {s['episodes']} x {s['seeds']} | {pct(sr['a'])} | {pct(sr['b'])} | "
                f"{100 * sr['diff']:+.1f} [{100 * sr['ci_low']:+.1f}, {100 * sr['ci_high']:+.1f}] | {pct(spl['a'])} | "
                f"{pct(spl['b'])} | {100 * spl['diff']:+.1f} [{100 * spl['ci_low']:+.1f}, {100 * spl['ci_high']:+.1f}] "
                f"| {sign['b_wins']} / {sign['a_wins']} | {sign['p_value']:.3g} | {pct(s['mde'])} | {s['verdict']} |"
            )
    return "\n".join(lines) + "\n"
