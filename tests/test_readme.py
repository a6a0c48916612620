"""Every command and code block of the README runs as written.

The blocks run in README order in one temporary folder (so later blocks use what earlier ones made),
shell blocks with `bash -euo pipefail`, Python blocks as scripts, in exactly the environment the README
tells a newcomer to make (`source .venv/bin/activate`): the venv's `bin` (its `ovon`, `python`) first on
PATH, no PYTHONPATH, and a `.venv` link to the venv in the folder, so that line itself runs as written.
The venv must be this checkout's (`make install`). Three documented departures keep it to minutes on a
2-core machine:

- SHRINK: sizes are substituted (scene counts, episodes per scene / split / run, seeds, render size,
  `--preset cpu-small` -> `tiny`, bench steps) and the README's fixed ports (50555, 50556) become ports
  free just before the first block naming each runs (a port taken by another run would make a block talk
  to someone else's server); the commands, options and code are otherwise unchanged. A block whose server
  finds its port taken after all ("Address already in use") runs once more on fresh ports.
- `make <target>` lines run as `make -n <target>` (a dry run: the target exists and expands), since
  `make test` inside the test suite would run the suite recursively.
- `python benchmarks/X.py OUT` lines run this checkout's scripts from a copy of `benchmarks/` in the temp
  folder, so their JSON never overwrites the committed results.

A Python block preceded by "Save the class below as `X.py`" is also written to `X.py`, and is run as a
module rather than as `__main__` (its main guard may start a server that a later block uses). `python` and
`ovon` on PATH are the venv's (this interpreter's).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.remote_agents import free_ports

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"

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
    (r"(ovon sim bench[^\n]*)", r"\1 --steps 40"),
    (r"(python benchmarks/vlfm_step.py)", r"\1 --houses 1 --episodes 2 --max-steps 40"),
]


README_PORTS = ("50555", "50556")
README_PORT = re.compile(r"\b(" + "|".join(README_PORTS) + r")\b")


class Ports(dict):
    """README port -> a port free when first asked for (just before the first block naming it runs, not
    minutes earlier), distinct from those handed out before."""

    def __missing__(self, readme_port: str) -> str:
        taken = set(self.values())
        self[readme_port] = port = next(str(p) for p in free_ports(len(taken) + 1) if str(p) not in taken)
        return port


def shrink(code: str, ports: Ports) -> str:
    for pattern, repl in SHRINK:
        code = re.sub(pattern, repl, code)
    return README_PORT.sub(lambda m: ports[m.group(1)], code)


def readme_blocks(text: str) -> list[tuple[str, str, str]]:
    """(language, code, text before the block) for every fenced block."""
    out = []
    for m in re.finditer(r"^```([A-Za-z]*)\n(.*?)^```", text, flags=re.S | re.M):
        before = text[: m.start()].rstrip().rsplit("\n\n", 1)[-1]
        out.append((m.group(1).lower() or "shell", m.group(2), before))
    return out


VENV_BIN = Path(sys.executable).parent  # .venv/bin when the suite runs as `make test` does


def newcomer_env(cwd: Path) -> dict:
    """What `source .venv/bin/activate` gives in the repository root: the venv's bin first on PATH (so
    `python` and `ovon` are the venv's), VIRTUAL_ENV set, no PYTHONPATH; `cwd/.venv` links to the venv."""
    if not (VENV_BIN / "ovon").exists() or sys.prefix == sys.base_prefix:
        pytest.fail(
            f"{sys.executable} is not a virtual environment with `ovon` installed; run the README test "
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


def _shell(code: str) -> str:
    """`make X` -> `make -n -C <repo> X` (see the module docstring)."""
    lines = []
    for line in code.splitlines():
        m = re.match(r"^(\s*)make (\S+)(.*)$", line)
        lines.append(f"{m.group(1)}make -n -C {ROOT} {m.group(2)}{m.group(3)}" if m else line)
    return "\n".join(lines) + "\n"


def run_block(
    lang: str, code: str, before: str, cwd: Path, env: dict, timeout: float, ports: Ports, saved_files: dict[Path, str]
) -> None:
    """Run one README block (shrunk); `saved_files` (file -> README code) collects the "Save ... as" files.
    A failure with "Address already in use" (a port picked free was taken before the block's server bound
    it) gets the ports it names picked anew, the saved files rewritten with them, and one more run."""
    res = _run_block_once(lang, code, before, cwd, env, timeout, ports, saved_files)
    named = set(README_PORT.findall(code))
    if res.returncode != 0 and named and "Address already in use" in res.stderr:
        for p in named:
            del ports[p]
        for path, original in saved_files.items():
            path.write_text(shrink(original, ports))
        res = _run_block_once(lang, code, before, cwd, env, timeout, ports, saved_files)
    code = shrink(code, ports)
    assert res.returncode == 0, (
        f"README {lang} block failed:\n{code}\n--- stdout\n{res.stdout[-3000:]}\n--- stderr\n{res.stderr[-3000:]}"
    )


def _run_block_once(
    lang: str, code: str, before: str, cwd: Path, env: dict, timeout: float, ports: Ports, saved_files: dict[Path, str]
) -> subprocess.CompletedProcess:
    original, code = code, shrink(code, ports)
    if lang in ("python", "py"):
        saved = re.search(r"[Ss]ave the class below as\s+`([\w./-]+\.py)`", before)
        if saved:
            saved_files[cwd / saved.group(1)] = original
            (cwd / saved.group(1)).write_text(code)
        script = cwd / "_block.py"
        script.write_text(code)
        cmd = ["python", str(script)]  # the `python` on the newcomer's PATH (the venv's)
        if saved:
            cmd = [
                "python",
                "-c",
                "import runpy, sys; runpy.run_path(sys.argv[1], run_name='readme_block')",
                str(script),
            ]
    elif lang in ("shell", "bash", "sh", "console"):
        script = cwd / "_block.sh"
        script.write_text(_shell(code))
        cmd = ["bash", "-euo", "pipefail", str(script)]
    else:
        pytest.fail(f"README block in an unknown language {lang!r}: teach tests/test_readme.py to run it")
    # its own process group, killed whole on a timeout: a server started with `&` must not outlive it
    proc = subprocess.Popen(
        cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"README {lang} block ran past {timeout:g} s:\n{code}\n--- stderr\n{err[-3000:]}")
    finally:
        try:  # whatever the block left in the background (a server whose trap did not run)
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def test_readme_blocks_are_all_runnable_kinds():
    blocks = readme_blocks(README.read_text())
    assert len(blocks) >= 5
    for lang, code, _ in blocks:
        assert lang in ("shell", "bash", "sh", "console", "python", "py"), lang
        assert "..." not in shrink(code, Ports()).replace('"..."', ""), f"placeholder in a README block:\n{code}"


def test_readme_has_no_merge_leftovers():
    text = README.read_text()
    assert not re.search(r"^(<<<<<<<|=======|>>>>>>>)( |$)", text, flags=re.M)


def test_readme_python_env_example_runs(tmp_path):
    """The Gymnasium example (the Python block's paragraphs up to the evaluation) runs as written, fast."""
    lang, code, _ = next(b for b in readme_blocks(README.read_text()) if "gym.make" in b[1])
    paragraphs = code.split("\n\n")
    head = "\n\n".join(paragraphs[: next(i for i, p in enumerate(paragraphs) if "evaluate(" in p)])
    assert "gym.make" in head
    script = tmp_path / "env_example.py"
    script.write_text(head)
    res = subprocess.run(
        ["python", str(script)], cwd=tmp_path, env=newcomer_env(tmp_path), capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr[-3000:]


@pytest.mark.slow
def test_every_readme_block_runs_as_written(tmp_path):
    env = newcomer_env(tmp_path)
    # `python benchmarks/X.py OUT` lines run this checkout's scripts; their JSON lands in the temp copy.
    shutil.copytree(ROOT / "benchmarks", tmp_path / "benchmarks", ignore=shutil.ignore_patterns("results"))
    (tmp_path / "benchmarks" / "results").mkdir()
    ports, saved_files = Ports(), {}
    for lang, code, before in readme_blocks(README.read_text()):
        run_block(lang, code, before, tmp_path, env, timeout=1800, ports=ports, saved_files=saved_files)
