"""Running the code blocks of the README and of docs/ as a newcomer would (used by tests/test_readme.py and
tests/test_docs_blocks.py).

The blocks of a page run in page order in one folder (later blocks use what earlier ones made), shell
blocks with `bash -euo pipefail`, Python blocks as scripts, in exactly the environment the docs tell a
newcomer to make (`source .venv/bin/activate`): the venv's `bin` (its `ovon`, `python`) first on PATH, no
PYTHONPATH, and a `.venv` link to the venv in the folder, so that line itself runs as written. The venv
must be this checkout's (`make install`). Documented departures keep it to minutes on a 2-core machine:

- SHRINK: sizes are substituted (scene counts, episodes per scene / split / run, seeds, render size,
  `--preset cpu-small` -> `tiny`, bench steps, training budgets) and the docs' fixed ports (50555, 50556)
  become ports free just before the first block naming each runs (a port taken by another run would make
  a block talk to someone else's server); the commands, options and code are otherwise unchanged. A block
  whose server finds its port taken after all ("Address already in use") runs once more on fresh ports.
- `make <target>` lines run as `make -n <target>` (a dry run: the target exists and expands), since
  `make test` inside the test suite would run the suite recursively.
- `python benchmarks/X.py OUT` lines run this checkout's scripts from a copy of `benchmarks/` in the
  folder, so their JSON never overwrites the committed results.
- A block right after the marker `<!-- docs-test: skip (REASON) -->` does not run (it needs data that
  cannot be had here, such as HM3D, or a GPU cluster); the reason is required.

A block after a paragraph saying "Save the ... below as `X`" is also written to `X`; a Python one is then
run as a module rather than as `__main__` (its main guard may start a server that a later block uses), a
block of another language (YAML) only written.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.remote_agents import free_ports

ROOT = Path(__file__).resolve().parents[1]

SMALL_DATASET = (
    "--set episodes_per_train_scene=4 --set episodes_per_val_split=6 "
    "--set viewpoints.render_size=48 --set viewpoints.max_viewpoints=4"
)
SHRINK: list[tuple[str, str]] = [
    (r"(--split train --count )\d+", r"\g<1>1"),
    (r"(--split val --count )\d+", r"\g<1>2"),
    (r"--preset fast", "--preset fast " + SMALL_DATASET),
    (r"episodes_per_train_scene=\d+", "episodes_per_train_scene=4"),
    (r"episodes_per_val_split=\d+", "episodes_per_val_split=6"),
    (r"--episodes \d+", "--episodes 2"),
    (r"episodes=\d+", "episodes=2"),
    (r"--seeds [0-9,]+", "--seeds 0"),
    (r"seeds=\([0-9, ]+\)", "seeds=(0,)"),
    (r"--preset cpu-small", "--preset tiny"),
    (r"--train-scenes \d+", "--train-scenes 1"),
    (r"--val-scenes \d+", "--val-scenes 1"),
    (r"--set max_updates=\d+", "--set max_updates=2"),
    (r"--set bc\.record_episodes=\d+", "--set bc.record_episodes=2"),
    (r"(ovon sim bench[^\n]*)", r"\1 --steps 40"),
    (r"(python benchmarks/vlfm_step.py)", r"\1 --houses 1 --episodes 2 --max-steps 40"),
]

DOC_PORTS = ("50555", "50556")
DOC_PORT = re.compile(r"\b(" + "|".join(DOC_PORTS) + r")\b")
SKIP = re.compile(r"<!--\s*docs-test:\s*skip\s*\(([^)]+)\)\s*-->")
SAVE = re.compile(r"[Ss]ave the .{0,40}?below\s+as\s+`([\w./-]+\.(?:py|yaml|yml|json|txt))`", re.S)
RUNNABLE = ("shell", "bash", "sh", "console", "python", "py")


class Ports(dict):
    """Docs port -> a port free when first asked for (just before the first block naming it runs, not
    minutes earlier), distinct from those handed out before."""

    def __missing__(self, doc_port: str) -> str:
        taken = set(self.values())
        self[doc_port] = port = next(str(p) for p in free_ports(len(taken) + 1) if str(p) not in taken)
        return port


def shrink(code: str, ports: Ports) -> str:
    for pattern, repl in SHRINK:
        code = re.sub(pattern, repl, code)
    return DOC_PORT.sub(lambda m: ports[m.group(1)], code)


@dataclass
class Block:
    lang: str
    code: str
    before: str  # the paragraph right before the fence
    skip: str | None  # the reason of a skip marker, None when the block runs
    saved_as: str | None  # "Save ... below as `X`": the file it is also written to


def blocks(text: str) -> list[Block]:
    """Every fenced block of a Markdown text (fences at the start of a line)."""
    out = []
    for m in re.finditer(r"^```([A-Za-z]*)[^\n]*\n(.*?)^```", text, flags=re.S | re.M):
        before = text[: m.start()].rstrip().rsplit("\n\n", 1)[-1]
        skip = SKIP.search(before.splitlines()[-1]) if before.strip() else None
        saved = SAVE.search(before)
        out.append(
            Block(
                lang=m.group(1).lower() or "shell",
                code=m.group(2),
                before=before,
                skip=skip.group(1).strip() if skip else None,
                saved_as=saved.group(1) if saved else None,
            )
        )
    return out


VENV_BIN = Path(sys.executable).parent  # .venv/bin when the suite runs as `make test` does


def newcomer_env(cwd: Path) -> dict:
    """What `source .venv/bin/activate` gives in the repository root: the venv's bin first on PATH (so
    `python` and `ovon` are the venv's), VIRTUAL_ENV set, no PYTHONPATH; `cwd/.venv` links to the venv."""
    if not (VENV_BIN / "ovon").exists() or sys.prefix == sys.base_prefix:
        pytest.fail(
            f"{sys.executable} is not a virtual environment with `ovon` installed; run the docs tests "
            "with the project's venv (`make install`, then `.venv/bin/pytest` or `make test-slow`)"
        )
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["PATH"] = f"{VENV_BIN}{os.pathsep}{env.get('PATH', '')}"
    env["VIRTUAL_ENV"] = sys.prefix
    env.setdefault("OMP_NUM_THREADS", "1")
    env.setdefault("LP_NUM_THREADS", "0")
    env["MPLBACKEND"] = "Agg"
    link = cwd / ".venv"
    if not link.exists():
        link.symlink_to(sys.prefix, target_is_directory=True)
    res = subprocess.run(
        ["python", "-c", "import ovon; print(ovon.__file__)"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    where = Path(res.stdout.strip() or "?").resolve()
    assert res.returncode == 0 and ROOT.resolve() in where.parents, (
        f"the venv's python imports ovon from {where}, not from this checkout {ROOT}: run `make install` here "
        f"({res.stderr[-500:]})"
    )
    return env


def prepare_folder(cwd: Path) -> dict:
    """The newcomer's environment in `cwd`, with a copy of `benchmarks/` (its results folder empty)."""
    env = newcomer_env(cwd)
    if not (cwd / "benchmarks").exists():
        shutil.copytree(ROOT / "benchmarks", cwd / "benchmarks", ignore=shutil.ignore_patterns("results"))
        (cwd / "benchmarks" / "results").mkdir()
    return env


def _shell(code: str) -> str:
    """`make X` -> `make -n -C <repo> X` (see the module docstring)."""
    lines = []
    for line in code.splitlines():
        m = re.match(r"^(\s*)make (\S+)(.*)$", line)
        lines.append(f"{m.group(1)}make -n -C {ROOT} {m.group(2)}{m.group(3)}" if m else line)
    return "\n".join(lines) + "\n"


def run_block(
    block: Block, where: str, cwd: Path, env: dict, timeout: float, ports: Ports, saved_files: dict[Path, str]
) -> None:
    """Run one block (shrunk); `saved_files` (file -> code as written) collects the "Save ... as" files.
    A failure with "Address already in use" (a port picked free was taken before the block's server bound
    it) gets the ports it names picked anew, the saved files rewritten with them, and one more run."""
    res = _run_block_once(block, where, cwd, env, timeout, ports, saved_files)
    named = set(DOC_PORT.findall(block.code))
    if res.returncode != 0 and named and "Address already in use" in res.stderr:
        for p in named:
            del ports[p]
        for path, original in saved_files.items():
            path.write_text(shrink(original, ports))
        res = _run_block_once(block, where, cwd, env, timeout, ports, saved_files)
    code = shrink(block.code, ports)
    assert res.returncode == 0, (
        f"{where}: {block.lang} block failed:\n{code}\n--- stdout\n{res.stdout[-3000:]}\n"
        f"--- stderr\n{res.stderr[-3000:]}"
    )


def _run_block_once(
    block: Block, where: str, cwd: Path, env: dict, timeout: float, ports: Ports, saved_files: dict[Path, str]
) -> subprocess.CompletedProcess:
    code = shrink(block.code, ports)
    if block.saved_as:
        path = cwd / block.saved_as
        path.parent.mkdir(parents=True, exist_ok=True)
        saved_files[path] = block.code
        path.write_text(code)
        if block.lang not in RUNNABLE:
            return subprocess.CompletedProcess([], 0, "", "")
    if block.lang in ("python", "py"):
        script = cwd / "_block.py"
        script.write_text(code)
        cmd = ["python", str(script)]  # the `python` on the newcomer's PATH (the venv's)
        if block.saved_as:
            cmd = ["python", "-c", "import runpy, sys; runpy.run_path(sys.argv[1], run_name='doc_block')", str(script)]
    elif block.lang in ("shell", "bash", "sh", "console"):
        script = cwd / "_block.sh"
        script.write_text(_shell(code))
        cmd = ["bash", "-euo", "pipefail", str(script)]
    else:
        pytest.fail(
            f"{where}: block in language {block.lang!r}: mark it skipped or teach tests/doc_blocks.py to run it"
        )
    # its own process group, killed whole on a timeout: a server started with `&` must not outlive it
    proc = subprocess.Popen(
        cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"{where}: {block.lang} block ran past {timeout:g} s:\n{code}\n--- stderr\n{err[-3000:]}")
    finally:
        try:  # whatever the block left in the background (a server whose trap did not run)
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)
