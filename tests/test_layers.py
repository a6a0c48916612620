"""The layers contract: every import between ovon packages points down the README's layer line.

Every `import` / `from ... import` in every module of ovon/ counts, those inside functions and under
TYPE_CHECKING included, and so do strings naming an ovon module (`"ovon.agents.random_agent:RandomAgent"`
in a plug-in table, `"ovon.cli.main"` run as a child process): a lazy import is still a dependency.
`|` separates packages of one layer that must not import each other; `->` goes up a layer. The README
states the same line (checked verbatim), so the rule a newcomer reads is the rule the suite enforces.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CONTRACT = (
    "atomic | config | geometry | lru | parallel | plugins -> runfolder -> scenes -> sim -> maps -> "
    "experts | models | task -> dataset | env -> agents -> evaluate | train | perception -> reports -> "
    "experiments -> cli"
)

# Declared edges against the line (importer module -> imported module), each with its reason. A declared
# edge that no longer exists fails the test too, so the list never outlives the code.
EXCEPTIONS = {
    (
        "ovon.experiments.plan",
        "ovon.cli.main",
    ): "validation parses each cell's command line with the real `ovon` parser, so a definition that "
    "resolves is one the command accepts",
    (
        "ovon.experiments.runner",
        "ovon.cli.main",
    ): "the runner executes cells as `python -m ovon.cli.main ...` child processes (not an import)",
}

_MODULE_STRING = re.compile(r"^ovon(?:\.\w+)+(?::[\w.]+)?$")


def parse_contract(line: str) -> list[set[str]]:
    """Layers from the bottom up, each a set of packages."""
    return [{p.strip() for p in layer.split("|")} for layer in line.split("->")]


def _modules(root: Path) -> dict[str, Path]:
    out = {}
    for path in sorted((root / "ovon").rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _resolve(module: str, node: ast.ImportFrom, is_pkg: bool) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_pkg else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def references(module: str, path: Path) -> list[tuple[str, int]]:
    """(ovon module named, line) for every import anywhere in the file and every module-naming string."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = _resolve(module, node, path.name == "__init__.py")
            found += [(f"{mod}.{a.name}", node.lineno) for a in node.names] or [(mod, node.lineno)]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and _MODULE_STRING.match(node.value):
            found.append((node.value.partition(":")[0], node.lineno))
    return [(name, line) for name, line in found if name == "ovon" or name.startswith("ovon.")]


def _package(name: str) -> str:
    """`ovon.sim.navgrid` -> "sim"; the root package (`ovon/__init__.py`: version + gym registration) -> ""."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else ""


def _owner(name: str, modules: dict[str, Path]) -> str:
    """The longest existing module that `name` (a module or module.attribute) lies in."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name


def violations(root: Path, contract: str, exceptions: dict) -> tuple[list[str], set]:
    """(one line per import against the contract, the declared exceptions that were used)."""
    layers = parse_contract(contract)
    level = {pkg: i for i, layer in enumerate(layers) for pkg in layer}
    modules = _modules(root)
    bad, used = [], set()
    for pkg in sorted({_package(m) for m in modules} - {""} - set(level)):
        bad.append(f"ovon.{pkg} is in no layer: add it to the contract (and README's line)")
    for module, path in modules.items():
        src = _package(module)
        if not src or src not in level:
            continue
        for name, line in references(module, path):
            target = _owner(name, modules)
            dst = _package(target)
            if not dst or dst == src or dst not in level or level[dst] < level[src]:
                continue
            if (module, target) in exceptions:
                used.add((module, target))
                continue
            how = "a sibling in its layer" if level[dst] == level[src] else "a layer above it"
            bad.append(f"{path.relative_to(root)}:{line}: ovon.{src} imports {target}, {how}")
    return bad, used


def test_imports_follow_the_layers() -> None:
    bad, used = violations(ROOT, CONTRACT, EXCEPTIONS)
    assert bad == [], "\n".join(bad)
    assert set(EXCEPTIONS) == used, f"declared exceptions no longer used: {sorted(set(EXCEPTIONS) - used)}"


def test_every_package_is_placed_exactly_once() -> None:
    layers = parse_contract(CONTRACT)
    names = [p for layer in layers for p in layer]
    assert len(names) == len(set(names))
    on_disk = {
        p.stem if p.suffix == ".py" else p.name
        for p in (ROOT / "ovon").iterdir()
        if (p.suffix == ".py" and p.name != "__init__.py") or (p / "__init__.py").exists()
    }
    on_disk |= {p.name for p in (ROOT / "ovon").iterdir() if p.is_dir() and any(p.glob("*.py"))}
    assert on_disk == set(names), (sorted(on_disk - set(names)), sorted(set(names) - on_disk))


def test_readme_states_the_contract_verbatim() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert f"`{CONTRACT}`" in " ".join(readme.split()), "README's layer line differs from tests/test_layers.py"
    for importer, imported in EXCEPTIONS:
        assert f"`{importer}`" in readme and f"`{imported}`" in readme, (importer, imported)


def test_the_checker_finds_upward_sibling_and_lazy_imports(tmp_path: Path) -> None:
    """On a made-up tree: an upward import inside a function, a sibling import, a plug-in string, and an
    unplaced package are each reported; a downward import and a declared exception are not."""
    files = {
        "ovon/__init__.py": "",
        "ovon/low/__init__.py": "",
        "ovon/low/a.py": "def f():\n    from ovon.high.b import g\n",
        "ovon/low/c.py": "import ovon.side.d\n",
        "ovon/low/e.py": "TABLE = {'x': 'ovon.high.b:Thing'}\n",
        "ovon/side/__init__.py": "",
        "ovon/side/d.py": "from . import __name__ as n\n",
        "ovon/high/__init__.py": "",
        "ovon/high/b.py": "from ovon.low import a\nfrom ovon.low.c import nothing\n",
        "ovon/high/ok.py": "from ovon.top import cli\n",
        "ovon/top/__init__.py": "",
        "ovon/top/cli.py": "",
        "ovon/stray.py": "",
    }
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    bad, used = violations(tmp_path, "low | side -> high -> top", {("ovon.high.ok", "ovon.top.cli"): "why"})
    assert bad == [
        "ovon.stray is in no layer: add it to the contract (and README's line)",
        "ovon/low/a.py:2: ovon.low imports ovon.high.b, a layer above it",
        "ovon/low/c.py:1: ovon.low imports ovon.side.d, a sibling in its layer",
        "ovon/low/e.py:1: ovon.low imports ovon.high.b, a layer above it",
    ]
    assert used == {("ovon.high.ok", "ovon.top.cli")}
