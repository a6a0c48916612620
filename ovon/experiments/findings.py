"""The paper's findings as rules over table entries, judged on our numbers and on the paper's own.

Why judge the paper's numbers too: it checks the rule (a rule that fails on the paper's table does not
state the paper's finding), and it shows beside our verdict what the paper found. Numbers are means over
seeds in % points; a verdict is "within noise" when a deciding gap is smaller than the two stds summed.
"""

from __future__ import annotations

import re
from collections.abc import Callable

from ovon.experiments.definitions import Check, Finding, parse_ref

Value = tuple[float, float]  # (mean, std) in %
Lookup = Callable[[str, str], Value | None]  # (ref, metric) -> value, None when not run
# (ref a, ref b, metric) -> the paired difference a - b on their shared episodes, in % points:
# {"diff", "ci_low", "ci_high", "p", "mde"}; None when the two did not run the same episodes (or did not run);
# mde: the SR difference those episodes detect (paired, 95%, 80% power), in % points
Paired = Callable[[str, str, str], dict | None]
# refs -> `ovon.reports.splits.split_spread` over those entries' episodes, each ref one group (so its "splits"
# and "pairs" name refs); None when any has not run. For rules over entries on different episodes (splits).
Spread = Callable[[tuple[str, ...]], dict | None]
PAIRED_BASE = (
    "paired: the per-episode difference on the episodes both ran, with a 95% bootstrap interval over episodes; "
    "a comparison holds when its interval excludes 0 in the claimed direction"
)
PAIRED_NOTE = (
    PAIRED_BASE + "; a verdict of not shown names the minimum detectable SR difference (MDE: paired, 95%, 80% "
    "power) of those episodes, below which a real difference would mostly go unseen"
)
# a report written before verdicts named their MDE, rendered again (`ovon experiment render`)
PAIRED_NOTE_BEFORE_MDE = (
    PAIRED_BASE + "; this report's paired verdicts were judged before they named their minimum detectable "
    "difference: the power line under the table gives it for the entries' episode count"
)

INTERVAL_NOTE = (
    "a rule across splits (flat, drop) compares entries on different episodes: its interval verdict gives the "
    "gap with a 95% bootstrap interval, each entry's episodes resampled on their own (unpaired, an episode's "
    "seeds together)"
)

SAME_SEEDS = "‡"
SAME_SEEDS_NOTE = (
    f"{SAME_SEEDS} every evaluation seed ran each episode to the same end (a deterministic agent, no noise): "
    "its std over seeds is 0 by construction and measures nothing, so none is printed; the paired intervals "
    "and detectable differences of the findings are over episodes"
)


def same_seeds_lines(rows: list[dict]) -> list[str]:
    """The note under a table (a blank line, then the note) when any of its entries is marked SAME_SEEDS."""
    marked = any((c.get("ours") or {}).get("seeds_identical") for r in rows for c in r["cells"].values())
    return ["", SAME_SEEDS_NOTE + "."] if marked else []


RULE_NOTE = (
    "means over evaluation seeds, in % points; 'within noise' where a deciding gap is smaller than the sum "
    "of the two standard deviations"
)


def rule_text(chk: Check) -> str:
    m = chk.metric.upper()
    if chk.kind == "best":
        return f"{m} of {chk.target} > {m} of each of {', '.join(chk.others)}"
    if chk.kind == "greater":
        plus = f" + {chk.margin:g}" if chk.margin else ""
        return "; ".join(f"{m} of {a} > {b}{plus}" for a, b in chk.pairs)
    if chk.kind == "flat":
        return f"max - min of {m} over {', '.join(chk.refs)} <= {chk.tolerance:g}"
    if chk.kind == "drop":
        return "; ".join(f"{m} of {a} - {b} >= {chk.tolerance:g}" for a, b in chk.pairs)
    drop_a = ", ".join(f"{a} -> {b}" for a, b in chk.pairs)
    drop_b = ", ".join(f"{a} -> {b}" for a, b in chk.against)
    return f"mean {m} drop over ({drop_a}) < mean {m} drop over ({drop_b})"


def _deciding(holds: bool, oks: list[bool], close: list[bool]) -> bool:
    """Whether the verdict is within noise: when it holds, any of its gaps could flip it; when it does not,
    only if every failing gap could (a clear loss elsewhere decides it)."""
    if holds:
        return any(close)
    return all(c for ok, c in zip(oks, close) if not ok)


def _gaps(pairs: list[tuple[Value, Value]], margin: float = 0.0) -> tuple[bool, bool, list[float]]:
    gaps = [a[0] - b[0] - margin for a, b in pairs]
    oks = [g > 0 for g in gaps]
    close = [abs(g) < a[1] + b[1] for g, (a, b) in zip(gaps, pairs)]
    return all(oks), _deciding(all(oks), oks, close), gaps


def paired_check(chk: Check, paired: Paired | None) -> dict | None:
    """The paired verdict of a `best` / `greater` check (same split, same episodes), else None: holds when
    every interval lies above the margin (0 unless the check sets one), does not hold when one lies below
    it, otherwise not shown."""
    if paired is None or chk.kind not in ("best", "greater"):
        return None
    pairs = [(chk.target, o) for o in chk.others] if chk.kind == "best" else list(chk.pairs)
    stats = [paired(a, b, chk.metric) for a, b in pairs]
    if any(st is None for st in stats):
        return None
    if all(st["ci_low"] > chk.margin for st in stats):
        verdict = "holds"
    elif any(st["ci_high"] < chk.margin for st in stats):
        verdict = "does not hold"
    else:
        mdes = [st["mde"] for st in stats if "mde" in st]
        named = f"; MDE {max(mdes):.1f} pts" if mdes else ""  # the largest: the comparison that decides it
        verdict = f"not shown (an interval includes {chk.margin:g}{named})"
    sign = " (SR sign test p {p:.2g})" if chk.metric == "sr" else ""
    numbers = "; ".join(f"{a} - {b} {interval_text(st)}" + sign.format(p=st["p"]) for (a, b), st in zip(pairs, stats))
    return {"verdict": verdict, "numbers": numbers}


def _gap(result: dict, a: str, b: str) -> tuple[float, float, float]:
    """SR(a) - SR(b) and its interval in % points from a `split_spread` result (its pairs are ordered high-low)."""
    p = next(p for p in result["pairs"] if {p["a"], p["b"]} == {a, b})
    d, lo, hi = 100 * p["diff"], 100 * p["ci"][0], 100 * p["ci"][1]
    return (d, lo, hi) if p["a"] == a else (-d, -hi, -lo)


def interval_check(chk: Check, spread: Spread | None) -> dict | None:
    """The episode-interval verdict of a `flat` / `drop` check, whose entries ran different episodes (splits),
    so the gap is unpaired: `flat` holds when the largest gap's interval lies at or below the tolerance and does
    not when it lies above; `drop` holds when every drop's interval lies at or above it and does not when one
    lies below; otherwise not shown. None for other kinds or where an entry has no episodes."""
    if spread is None or chk.kind not in ("flat", "drop"):
        return None
    tol = chk.tolerance
    if chk.kind == "flat":
        res = spread(tuple(chk.refs))
        if res is None:
            return None
        sp = res["spread"]
        d, (lo, hi) = 100 * sp["diff"], (100 * x for x in sp["ci"])  # the largest gap, high minus low
        unshown = f"not shown (the interval includes {tol:g})"
        verdict = "holds" if hi <= tol else "does not hold" if lo > tol else unshown
        return {"verdict": verdict, "numbers": f"largest gap {sp['a']} - {sp['b']} {d:+.1f} [{lo:+.1f}, {hi:+.1f}]"}
    gaps = []
    for a, b in chk.pairs:
        res = spread((a, b))
        if res is None:
            return None
        gaps.append((a, b, *_gap(res, a, b)))
    if all(lo >= tol for *_, lo, _ in gaps):
        verdict = "holds"
    elif any(hi < tol for *_, hi in gaps):
        verdict = "does not hold"
    else:
        verdict = f"not shown (an interval includes {tol:g})"
    numbers = "; ".join(f"{a} - {b} {d:+.1f} [{lo:+.1f}, {hi:+.1f}]" for a, b, d, lo, hi in gaps)
    return {"verdict": verdict, "numbers": numbers}


def interval_text(st: dict) -> str:
    """A paired difference as the reports print it: '+6.0 [+1.8, +10.5]'."""
    return f"{st['diff']:+.1f} [{st['ci_low']:+.1f}, {st['ci_high']:+.1f}]"


# `{ROW @ COLUMN}` or `{ROW @ COLUMN - ROW @ COLUMN}` in a finding's `differs` sentence
_SENTENCE_REF = re.compile(r"\{([^{}]*@[^{}]*)\}")
NOT_RUN = "(not run)"


def _quoted(m: re.Match) -> tuple[str, ...]:
    """A quote's references: (ref,) or (ref a, ref b) for `{A - B}`."""
    return tuple(x.strip() for x in m.group(1).split(" - "))


def sentence_refs(text: str, where: str) -> list[tuple[str, ...]]:
    """The table references a `differs` sentence quotes, each as (ref,) or (ref a, ref b); raises
    DefinitionError (naming `where`) on one that is not 'ROW @ COLUMN'."""
    out = []
    for m in _SENTENCE_REF.finditer(text):
        parts = _quoted(m)
        if len(parts) > 2:
            parts = (m.group(1),)  # not 'A - B': parse_ref names it
        for ref in parts:
            parse_ref(ref, where)
        out.append(parts)
    return out


def fill_sentence(text: str, look: Lookup, paired: Paired | None = None) -> str:
    """A `differs` sentence with its quoted table values filled in from this run, so that the why never
    copies a result by hand: `{DAgRL @ val_seen}` -> '15.0' (SR), `{A @ c - B @ c}` -> the paired difference
    with its interval ('+4.8 [+0.5, +9.0]'), or the plain difference where the two cannot be paired."""

    def value(m: re.Match) -> str:
        parts = _quoted(m)
        if len(parts) == 1:
            v = look(parts[0], "sr")
            return NOT_RUN if v is None else f"{v[0]:.1f}"
        st = paired(parts[0], parts[1], "sr") if paired is not None else None
        if st is not None:
            return interval_text(st)
        a, b = look(parts[0], "sr"), look(parts[1], "sr")
        return NOT_RUN if a is None or b is None else f"{a[0] - b[0]:+.1f}"

    return _SENTENCE_REF.sub(value, text)


def judge_check(chk: Check, look: Lookup, paired: Paired | None = None, spread: Spread | None = None) -> dict:
    """{"verdict": holds | does not hold | not run, "within_noise": bool, "numbers": text}."""
    refs = {r for r in (chk.target, *chk.others, *chk.refs, *(x for p in (*chk.pairs, *chk.against) for x in p)) if r}
    values = {r: look(r, chk.metric) for r in refs}
    missing = sorted(r for r, v in values.items() if v is None)
    if missing:
        return {"verdict": "not run", "within_noise": False, "numbers": f"missing: {', '.join(missing)}"}
    v = {r: val for r, val in values.items() if val is not None}

    def show(r: str) -> str:
        return f"{r} {v[r][0]:.1f}"

    if chk.kind in ("best", "greater"):
        pairs = [(chk.target, o) for o in chk.others] if chk.kind == "best" else list(chk.pairs)
        holds, noisy, _ = _gaps([(v[a], v[b]) for a, b in pairs], chk.margin)  # margin: only on greater
        numbers = "; ".join(f"{show(a)} vs {show(b)}" for a, b in pairs)
    elif chk.kind == "flat":
        means = [v[r][0] for r in chk.refs]
        width = max(means) - min(means)
        holds = width <= chk.tolerance
        hi, lo = max(chk.refs, key=lambda r: v[r][0]), min(chk.refs, key=lambda r: v[r][0])
        noisy = abs(width - chk.tolerance) < v[hi][1] + v[lo][1]
        numbers = ", ".join(show(r) for r in chk.refs) + f" (spread {width:.1f})"
    elif chk.kind == "drop":
        drops = [(v[a][0] - v[b][0], v[a][1] + v[b][1]) for a, b in chk.pairs]
        oks = [d >= chk.tolerance for d, _ in drops]
        holds = all(oks)
        noisy = _deciding(holds, oks, [abs(d - chk.tolerance) < s for d, s in drops])
        numbers = "; ".join(f"{show(a)} -> {v[b][0]:.1f} (drop {v[a][0] - v[b][0]:.1f})" for a, b in chk.pairs)
    else:  # smaller_drop
        da = [v[a][0] - v[b][0] for a, b in chk.pairs]
        db = [v[a][0] - v[b][0] for a, b in chk.against]
        ma, mb = sum(da) / len(da), sum(db) / len(db)
        sa = max(v[a][1] + v[b][1] for a, b in chk.pairs)
        sb = max(v[a][1] + v[b][1] for a, b in chk.against)
        holds = ma < mb
        noisy = abs(mb - ma) < sa + sb
        each_a, each_b = ", ".join(f"{d:.1f}" for d in da), ", ".join(f"{d:.1f}" for d in db)
        numbers = f"mean drop {ma:.1f} ({each_a}) vs {mb:.1f} ({each_b})"
    out = {"verdict": "holds" if holds else "does not hold", "within_noise": bool(noisy), "numbers": numbers}
    pv = paired_check(chk, paired)
    if pv is not None:
        out["paired"] = pv
    iv = interval_check(chk, spread)
    if iv is not None:
        out["interval"] = iv
    return out


def judge(finding: Finding, look: Lookup, paired: Paired | None = None, spread: Spread | None = None) -> dict:
    """A finding holds when every check holds; "not run" when any check lacks numbers. Checks that compare runs
    on the same episodes also get a paired verdict (`paired_check`), checks across splits an unpaired interval
    verdict (`interval_check`), beside the two-std rule."""
    checks = [{"rule": rule_text(c), **judge_check(c, look, paired, spread)} for c in finding.checks]
    verdicts = {c["verdict"] for c in checks}
    verdict = "not run" if "not run" in verdicts else ("does not hold" if "does not hold" in verdicts else "holds")
    noisy = verdict != "not run" and _deciding(
        verdict == "holds", [c["verdict"] == "holds" for c in checks], [c["within_noise"] for c in checks]
    )
    return {"verdict": verdict, "within_noise": noisy, "checks": checks}
