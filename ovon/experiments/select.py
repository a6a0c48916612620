"""Which cells a run takes: `--only CELL,...` (with what they need) and `--shard i/n`.

Why shards are whole dependency chains: a shard never waits for another shard's output, so shards run
on separate machines without a shared file system (each prepares the same deterministic data), and
on one shared root they never train the same cell twice (cells shared by chains are locked).
"""

from __future__ import annotations

from ovon.experiments.definitions import DefinitionError
from ovon.experiments.plan import Plan

DATA = "data:data"
WEIGHT = {"train": 4, "eval": 1}  # a training cell costs several evaluations


def parse_shard(text: str | None) -> tuple[int, int] | None:
    """ "i/n" (0-based: 0/2 and 1/2 are the two halves) -> (i, n)."""
    if not text:
        return None
    i, sep, n = text.partition("/")
    try:
        index, count = int(i), int(n)
    except ValueError:
        index, count = -1, 0
    if not sep or count < 1 or not 0 <= index < count:
        raise DefinitionError(
            f"--shard {text!r}: expected i/n with 0 <= i < n (0-based), e.g. --shard 0/2 and "
            "--shard 1/2 on two machines"
        )
    return index, count


def match_cells(plan: Plan, names: list[str], flag: str = "--only") -> list[str]:
    """Cell ids for names: `train:NAME`, `eval:NAME` or a bare NAME (its training and evaluation cells).
    `flag`: the option the names came from (--only, --redo), for the message naming an unknown one."""
    out: list[str] = []
    for name in names:
        hits = [name] if name in plan.cells else [c for c in (f"train:{name}", f"eval:{name}") if c in plan.cells]
        if name == "data":
            hits = [DATA]
        if not hits:
            valid = sorted({c.split(":", 1)[1] for c in plan.cells})
            raise DefinitionError(
                f"{flag}: no cell {name!r} in {plan.names}; valid: {', '.join(valid)} (or "
                f"train:NAME / eval:NAME); fix: {flag} one of them"
            )
        out += [h for h in hits if h not in out]
    return out


def with_prerequisites(plan: Plan, ids: list[str]) -> list[str]:
    need = set(ids)
    stack = list(ids)
    while stack:
        for dep in plan.cells[stack.pop()].deps:
            if dep not in need:
                need.add(dep)
                stack.append(dep)
    return [c for c in plan.cells if c in need]


def components(plan: Plan, ids: list[str]) -> list[list[str]]:
    """Groups of `ids` linked by dependencies (the data cell left out), in plan order."""
    parent = {c: c for c in ids if c != DATA}

    def find(c: str) -> str:
        while parent[c] != c:
            parent[c] = parent[parent[c]]
            c = parent[c]
        return c

    for c in parent:
        for d in plan.cells[c].deps:
            if d in parent:
                parent[find(c)] = find(d)
    groups: dict[str, list[str]] = {}
    for c in plan.cells:
        if c in parent:
            groups.setdefault(find(c), []).append(c)
    return list(groups.values())


def shard_of(plan: Plan, ids: list[str], index: int, count: int) -> list[str]:
    """The cells of shard `index` of `count`: whole components, heaviest first onto the lightest shard
    (deterministic: ties go to the lower shard and the earlier component)."""
    comps = components(plan, ids)
    weight = [sum(WEIGHT.get(plan.cells[c].kind, 1) for c in comp) for comp in comps]
    order = sorted(range(len(comps)), key=lambda k: (-weight[k], k))
    load = [0] * count
    mine: set[str] = set()
    for k in order:
        target = min(range(count), key=lambda s: (load[s], s))
        load[target] += weight[k]
        if target == index:
            mine.update(comps[k])
    return [c for c in ids if c in mine]


def select(plan: Plan, only: list[str] | None = None, shard: tuple[int, int] | None = None) -> list[str]:
    """The ids this run takes, the data cell first, dependencies before their users."""
    ids = with_prerequisites(plan, match_cells(plan, only)) if only else list(plan.cells)
    if shard is not None:
        ids = shard_of(plan, ids, *shard)
    return [DATA, *(c for c in ids if c != DATA)]
