"""Adversarial campaign over the `ovon` command line: a few hundred bad (and good) inputs and faults.

    python tests/fuzz/cli_campaign.py --out /tmp/campaign.json [--work /tmp/campaign] [--only evaluate]

Every case runs `python -m ovon.cli.main ...` in a subprocess on a tiny world (3 procedural houses, their
val episodes, a tiny trained policy) and is classified:

- clear_error: exit != 0, stderr is one `error:` line (warnings aside) naming the case's key/file/value;
- right_result: exit 0 (or the documented exit 1 of a failed `dataset validate`) and the outputs check
  out (episode counts, byte-identical files after a kill, records never lost);
- vague_error: one error line that misses what the case is about; traceback: a Python traceback or an
  "internal error"; silent_wrong: exit 0 where an error was due, or wrong outputs; hang: over the time
  limit; data_loss: complete records or files that were there before are gone.

Kill rounds SIGKILL the main process of `evaluate` / `dataset generate` at random moments, re-run, and
compare with an uninterrupted run (byte for byte), and look for orphan worker processes.
Prints a table and writes the JSON report (per case: argv, expectation, outcome, stderr line).
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = 420
BAD = ("traceback", "silent_wrong", "hang", "data_loss", "vague_error")


@dataclass
class Case:
    family: str
    argv: list[str]
    expect: str  # "error" | "ok" | "fail1" (dataset validate reports problems: exit 1)
    needles: tuple[str, ...] = ()  # the error line must contain each
    check: str = ""  # name of an output check for "ok"
    out: str = ""  # output folder of the case (must not be created by a refused command)
    preserve: str = ""  # folder whose complete records / files must survive
    outcome: str = ""
    detail: str = ""
    seconds: float = 0.0


@dataclass
class World:
    work: Path
    scenes: Path = field(init=False)
    data: Path = field(init=False)
    policy: Path = field(init=False)


def ovon_cmd(argv: list[str]) -> list[str]:
    return [sys.executable, "-m", "ovon.cli.main", *argv]


def env() -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT)
    e.setdefault("OMP_NUM_THREADS", "1")
    e.setdefault("LP_NUM_THREADS", "0")
    return e


# ----------------------------------------------------------------------------------------------------
# the tiny world


def build_world(work: Path) -> World:
    sys.path.insert(0, str(ROOT))
    from ovon.dataset.generate import generate
    from ovon.dataset.io import VAL_SPLITS
    from tests.conftest import tiny_generation_config, write_tiny_scenes

    w = World(work)
    w.scenes, w.data, w.policy = work / "world" / "ovon_world", work / "episodes", work / "policy"
    if not w.scenes.exists():
        write_tiny_scenes(w.scenes)
    if not (w.data / "val_seen").exists():
        generate(w.scenes, w.data, tiny_generation_config(), splits=VAL_SPLITS, workers=2, progress=False)
    if not (w.policy / "policy.pt").exists():
        subprocess.run(
            ovon_cmd(["train", "--algo", "dagger", "--preset", "tiny", "--procedural", "0-1", "--out", str(w.policy)]),
            env=env(),
            check=True,
            capture_output=True,
            cwd=work,
        )
    return w


def corrupt_datasets(w: World) -> dict[str, Path]:
    """Copies of the dataset, each broken one way (what an episode file from elsewhere can hold)."""
    base = w.work / "bad"
    out: dict[str, Path] = {}

    def copy(name: str) -> Path:
        d = base / name
        if d.exists():
            shutil.rmtree(d)
        shutil.copytree(w.data, d, ignore=shutil.ignore_patterns(".cache"))
        out[name] = d
        return d

    def shard(d: Path, split: str = "val_seen") -> Path:
        return sorted((d / split / "content").glob("*.json.gz"))[0]

    def edit(d: Path, fn, split: str = "val_seen", raw: bytes | None = None) -> None:
        p = shard(d, split)
        if raw is not None:
            p.write_bytes(raw)
            return
        doc = json.loads(gzip.decompress(p.read_bytes()))
        fn(doc)
        p.write_bytes(gzip.compress(json.dumps(doc).encode()))

    e0 = lambda d: d["episodes"][0]  # noqa: E731
    edit(copy("dup_ids"), lambda d: d["episodes"][1].__setitem__("episode_id", e0(d)["episode_id"]))
    edit(copy("nan_geodesic"), lambda d: e0(d)["info"].__setitem__("geodesic_distance", float("nan")))
    edit(copy("nan_start"), lambda d: e0(d).__setitem__("start_position", [float("nan"), 0, 0]))
    edit(copy("huge_start"), lambda d: e0(d).__setitem__("start_position", [1e308, 0, 0]))
    edit(copy("string_geodesic"), lambda d: e0(d)["info"].__setitem__("geodesic_distance", "far"))
    edit(copy("zero_rotation"), lambda d: e0(d).__setitem__("start_rotation", [0, 0, 0, 0]))
    edit(copy("non_unit_rotation"), lambda d: e0(d).__setitem__("start_rotation", [0, 0.5, 0, 0.5]))
    edit(copy("tilted_rotation"), lambda d: e0(d).__setitem__("start_rotation", [0.7071068, 0, 0, 0.7071068]))
    edit(copy("off_map_start"), lambda d: e0(d).__setitem__("start_position", [500.0, 0.0, 500.0]))
    edit(copy("empty_category"), lambda d: e0(d).__setitem__("object_category", ""))

    def no_vps(d):
        ep = e0(d)
        for g in d["goals_by_category"][f"{Path(ep['scene_id']).name}_{ep['object_category']}"]:
            g["view_points"] = []

    edit(copy("goal_without_viewpoints"), no_vps)
    edit(copy("escape_dotdot"), lambda d: [e.__setitem__("scene_id", "../../../etc/passwd") for e in d["episodes"]])
    edit(copy("escape_absolute"), lambda d: [e.__setitem__("scene_id", "/etc/passwd") for e in d["episodes"]])
    edit(copy("not_json"), None, raw=gzip.compress(b'{"episodes": [1, '))
    edit(copy("not_gzip"), None, raw=b"plain text, not gzip")
    edit(copy("deep_json"), None, raw=gzip.compress(b"[" * 200000 + b"]" * 200000))
    edit(copy("wrong_types"), lambda d: e0(d).__setitem__("start_position", "abc"))
    edit(copy("missing_key"), lambda d: e0(d).pop("scene_id"))
    d = copy("empty_split")
    for p in (d / "val_seen" / "content").glob("*.json.gz"):
        p.unlink()
    shutil.rmtree(copy("no_content") / "val_seen" / "content")
    return out


# ----------------------------------------------------------------------------------------------------
# cases


def evaluate_cases(w: World, rnd: random.Random) -> list[Case]:
    cases: list[Case] = []
    n = [0]

    def base(out: str | None = None, agent: str = "random") -> tuple[list[str], str]:
        n[0] += 1
        out = out or str(w.work / "runs" / f"e{n[0]}")
        return [
            "evaluate",
            "--agent",
            agent,
            "--data",
            str(w.data),
            "--scenes",
            str(w.scenes),
            "--no-progress",
            "--workers",
            "1",
            "--set",
            "task.max_steps=40",
            "--out",
            out,
        ], out

    def err(extra: list[str], *needles: str, agent: str = "random") -> None:
        argv, out = base(agent=agent)
        cases.append(Case("evaluate", argv + extra, "error", needles, out=out))

    def ok(extra: list[str], check: str = "counts", agent: str = "random") -> None:
        argv, out = base(agent=agent)
        cases.append(
            Case(
                "evaluate",
                argv + extra + ["--splits", "val_seen", "--episodes", "2"]
                if "--splits" not in extra and "--episodes" not in extra
                else argv + extra,
                "ok",
                check=check,
                out=out,
            )
        )

    for v in ["-1", "0", "abc", "1.5", "", "1e400", "nan", "-0", "0x10", "1,2"]:
        err(["--episodes", v], "--episodes")
    for v in ["", ",", "a", "-1", "0,0", "1.5", "0,,a", "1e400", "[0]", "0;1"]:
        err(["--seeds", v], "--seeds")
    for v in ["", ",", "val_nope", "../../etc", "/abs", "val_seen,val_seen", ".", "..", "val seen", "train"]:
        err(["--splits", v], "split")
    for v in ["0", "-1", "abc", "2.5", "100000"]:
        err(["--workers", v], "--workers")
    err(["--executor", "dask"], "--executor")
    for v in ["wind", "actuation:foo", "actuation:ilqr*abc", "odometry:1", "actuation:ilqr*-1", "actuation:*1e400"]:
        err(["--noise", v], "--noise")
    for key, val, needle in [
        ("task.success_distance", "-1", "task.success_distance"),
        ("task.success_distance", "0", "success_distance"),
        ("task.max_steps", "0", "task.max_steps"),
        ("task.max_steps", "-5", "task.max_steps"),
        ("task.max_steps", "1e400", "task.max_steps"),
        ("task.max_steps", "abc", "task.max_steps"),
        ("task.max_steps", "2.5", "task.max_steps"),
        ("task.seen_fraction", "2", "task.seen_fraction"),
        ("task.reward.kind", "x", "task.reward.kind"),
        ("sim.camera.width", "0", "sim.camera.width"),
        ("sim.camera.width", "-160", "sim.camera.width"),
        ("sim.camera.width", "100000", "sim.camera.width"),
        ("sim.camera.height", "0", "sim.camera.height"),
        ("sim.camera.hfov_deg", "180", "sim.camera.hfov_deg"),
        ("sim.camera.hfov_deg", "0", "sim.camera.hfov_deg"),
        ("sim.camera.hfov_deg", ".nan", "hfov_deg"),
        ("sim.camera.min_depth", "9", "sim.camera.min_depth"),
        ("sim.camera.backend", "vulkan", "backend"),
        ("sim.agent.forward_step", "0", "sim.agent.forward_step"),
        ("sim.agent.radius", "-0.1", "radius"),
        ("sim.agent.turn_angle_deg", "0", "turn_angle_deg"),
        ("sim.nav.cell_size", "0", "sim.nav.cell_size"),
        ("sim.nav.cell_size", "1e-9", "cell_size"),
        ("sim.noise.actuation", "wind", "sim.noise.actuation"),
        ("sim.noise.odometry", "maybe", "sim.noise.odometry"),
        ("sim.camrea.width", "3", "camrea"),
        ("sim", "3", "sim"),
        ("episodes", "3", "episodes"),
        ("task", "", "task"),
        ("", "1", "override"),
        ("sim.camera.width", "[" * 3000 + "]" * 3000, "sim.camera.width"),
    ]:
        err(["--set", f"{key}={val}"], needle)
    err(["--set", "novalue"], "key=value")
    for extra, needle in [
        (["--agent-arg", "bogus=1"], "bogus"),
        (["--agent-arg", "novalue"], "--agent-arg"),
        (["--agent-arg", "=1"], "--agent-arg"),
        (["--agent-arg", "stop_probability=abc"], "stop_probability"),
        (["--agent-arg", "seed=" + "[" * 3000 + "]" * 3000], "agent 'random'"),
        (["--agent-arg", "seed=-1"], "seed"),
    ]:
        err(extra, needle)
    for agent, needle in [
        ("nope", "nope"),
        ("json:JSONDecoder", "JSONDecoder"),
        ("os:system", "os:system"),
        ("x:", "x:"),
        (":Y", ":Y"),
        ("../a:B", "../a:B"),
        ("ovon.agents:BUILTIN", "BUILTIN"),
        ("no_such_mod:Agent", "no_such_mod"),
        ("ovon.agents.base:Agent", "Agent"),
        ("policy", "--checkpoint"),
    ]:
        err([], needle, agent=agent)
    garbage = w.work / "garbage.pt"
    garbage.write_bytes(b"\x80\x04 not a checkpoint")
    truncated = w.work / "truncated.pt"
    truncated.write_bytes((w.policy / "policy.pt").read_bytes()[:2000])
    for ckpt, needle in [
        (garbage, "--checkpoint"),
        (truncated, "--checkpoint"),
        (w.work / "nope.pt", "nope.pt"),
        (w.work, "--checkpoint"),
        (Path("/etc/passwd"), "--checkpoint"),
    ]:
        err(["--checkpoint", str(ckpt)], needle, agent="policy")
    afile = w.work / "afile.txt"
    afile.write_text("keep")
    argv, _ = base(str(afile))
    cases.append(Case("evaluate", argv, "error", ("--out", "afile.txt"), preserve=str(afile)))
    argv, _ = base("/proc/ovon_no_write")
    cases.append(Case("evaluate", argv, "error", ("/proc/ovon_no_write",)))
    for what in (
        ["--data", str(w.work / "missing")],
        ["--data", str(afile)],
        ["--scenes", str(w.work / "none")],
        ["--data", str(w.work / "runs")],
    ):
        err(what, what[0])
    bad = corrupt_datasets(w)
    refuse = {
        "nan_start": "start_position",
        "huge_start": "start_position",
        "escape_dotdot": "scenes root",
        "escape_absolute": "scenes root",
        "not_json": "not valid JSON",
        "not_gzip": "gzip",
        "deep_json": "nested",
        "wrong_types": "start_position",
        "missing_key": "scene_id",
        "empty_split": "no <scene>.json.gz",
        "no_content": "content/",
    }
    for name, d in bad.items():
        argv, out = base()
        argv = [a if a != str(w.data) else str(d) for a in argv] + ["--splits", "val_seen"]
        if name in refuse:
            cases.append(Case("evaluate-data", argv, "error", (refuse[name],), out=out))
        else:  # skipped with a counted warning: the other episodes run; --strict refuses naming the file
            cases.append(Case("evaluate-data", argv, "ok", check="skipped", out=out))
            if name in ("string_geodesic", "off_map_start", "dup_ids"):
                argv, out = base()
                argv = [a if a != str(w.data) else str(d) for a in argv] + ["--splits", "val_seen", "--strict"]
                cases.append(Case("evaluate-data", argv, "error", (".json.gz", "episode", "--strict"), out=out))
    # right results
    ok([])
    ok(["--splits", "val_seen,val_unseen", "--seeds", "0,1", "--episodes", "3"])
    ok(["--splits", "val_unseen_hard", "--episodes", "2"])  # the alias of val_unseen
    ok(["--episodes", "99999999999", "--splits", "val_seen"])
    ok(["--seeds", " 3 ", "--splits", "val_seen", "--episodes", "1"])
    ok(["--noise", "actuation:movebase*0.5,odometry"])
    ok(["--set", "sim.camera.width=64", "--set", "sim.camera.height=48", "--set", "task.success_distance=0.5"])
    ok(["--agent-arg", "stop_probability=0.5", "--agent-arg", "seed=3"])
    ok(["--checkpoint", str(w.policy / "policy.pt")], agent="policy")
    ok(["--checkpoint", str(w.policy)], agent="policy")
    ok([], agent="tests.example_agent:TurnInPlaceAgent")
    ok(["--workers", "2"])
    # resume semantics on one folder
    shared = str(w.work / "runs" / "shared")
    first, _ = base(shared)
    cases.append(Case("resume", first + ["--splits", "val_seen", "--episodes", "4"], "ok", check="counts", out=shared))
    again, _ = base(shared)
    cases.append(
        Case("resume", again + ["--splits", "val_seen", "--episodes", "4"], "ok", check="counts", preserve=shared)
    )
    more, _ = base(shared)
    cases.append(
        Case(
            "resume",
            more + ["--splits", "val_seen,val_unseen", "--episodes", "4", "--seeds", "0,1"],
            "ok",
            check="counts",
            preserve=shared,
        )
    )
    for extra, needle in [
        (["--set", "task.max_steps=41"], "task.max_steps 40 -> 41"),
        (["--set", "sim.camera.width=64"], "sim.camera.width"),
        (["--noise", "odometry"], "sim.noise.odometry"),
    ]:
        argv, _ = base(shared)
        cases.append(Case("resume", argv + extra, "error", (needle,), preserve=shared))
    argv, _ = base(shared, agent="shortest-path")
    cases.append(Case("resume", argv, "error", ('agent "random" -> "shortest-path"',), preserve=shared))
    spelled = [
        "evaluate",
        "--agent",
        "random",
        "--data",
        str(w.data) + "/",
        "--scenes",
        os.path.relpath(w.scenes, ROOT) + "/",
        "--no-progress",
        "--set",
        "task.max_steps=40",
        "--workers",
        "2",
        "--splits",
        "val_seen",
        "--episodes",
        "4",
        "--out",
        shared,
    ]
    cases.append(Case("resume", spelled, "ok", check="counts", preserve=shared))
    # random combinations (an independent oracle says which must run)
    for _ in range(40):
        cases.append(random_evaluate_case(w, rnd, base))
    return cases


EPISODES = ["1", "2", "0", "-1", "", "x", "2.0", "1e3"]
SEEDS = ["0", "1", "0,1", "", "0,0", "-1", "a", " 3 "]
SPLITS = ["val_seen", "val_unseen", "val_seen,val_unseen", "", "val_seen,val_seen", "val_nope", "x/../y"]
SETS = [
    "task.max_steps=30",
    "task.max_steps=0",
    "task.success_distance=0.5",
    "task.success_distance=-1",
    "sim.camera.width=32",
    "sim.camera.width=0",
    "sim.camera.hfov_deg=179",
    "sim.camera.hfov_deg=180",
    "sim.agent.radius=0.2",
    "sim.agent.radius=0",
    "task.seen_fraction=2",
    "task.reward.kind=sparse",
    "x=1",
]
GOOD_SETS = {
    "task.max_steps=30",
    "task.success_distance=0.5",
    "sim.camera.width=32",
    "sim.camera.hfov_deg=179",
    "sim.agent.radius=0.2",
    "task.reward.kind=sparse",
}


def random_evaluate_case(w: World, rnd: random.Random, base) -> Case:
    argv, out = base()
    e, s, sp = rnd.choice(EPISODES), rnd.choice(SEEDS), rnd.choice(SPLITS)
    sets = rnd.sample(SETS, rnd.randint(0, 2))
    argv += ["--episodes", e, "--seeds", s, "--splits", sp]
    for x in sets:
        argv += ["--set", x]
    valid = True
    try:
        valid &= float(e) == int(float(e)) and float(e) >= 1
    except ValueError:
        valid = False
    seeds = [x.strip() for x in s.split(",") if x.strip()]
    valid &= (
        bool(seeds) and all(x.isdigit() for x in seeds) and len(set(map(int, seeds))) == len(seeds) if seeds else False
    )
    splits = [x for x in sp.split(",") if x]
    valid &= bool(splits) and len(set(splits)) == len(splits) and all(x in ("val_seen", "val_unseen") for x in splits)
    valid &= all(x in GOOD_SETS for x in sets)
    return Case("evaluate-random", argv, "ok" if valid else "error", check="counts" if valid else "", out=out)


def dataset_cases(w: World) -> list[Case]:
    cases: list[Case] = []
    n = [0]

    def gen(*extra: str, out: str | None = None) -> tuple[list[str], str]:
        n[0] += 1
        out = out or str(w.work / "gen" / f"g{n[0]}")
        return ["dataset", "generate", "--scenes", str(w.scenes), "--out", out, "--no-progress", *extra], out

    for key, val in [
        ("episodes_per_val_split", "-5"),
        ("episodes_per_val_split", "0"),
        ("episodes_per_train_scene", "abc"),
        ("seed", "-1"),
        ("seed", "1.5"),
        ("decimals", "0"),
        ("viewpoints.render_size", "0"),
        ("viewpoints.render_size", "100000"),
        ("viewpoints.hfov_deg", "0"),
        ("viewpoints.hfov_deg", "180"),
        ("viewpoints.grid_step", "0"),
        ("viewpoints.tilts_deg", "[]"),
        ("viewpoints.tilts_deg", "[100]"),
        ("viewpoints.min_score", "1"),
        ("viewpoints.max_viewpoints", "-1"),
        ("viewpoints.backend", "x"),
        ("starts.min_geodesic", "40"),
        ("starts.max_geodesic", "0"),
        ("starts.max_tries", "0"),
        ("splits.holdout_fraction", "1"),
        ("splits.holdout_fraction", "0"),
        ("splits.similarity_threshold", "2"),
        ("splits.children", "maybe"),
        ("nope", "1"),
        ("viewpoints.render_sise", "64"),
    ]:
        argv, out = gen("--set", f"{key}={val}")
        cases.append(Case("generate", argv, "error", (key.split(".")[-1],), out=out))
    for extra, needle in [
        (["--categories", str(w.work / "missing.json")], "missing.json"),
        (["--split", "val_nope"], "--split"),
        (["--split", "train", "--split", "train"], "--split"),
        (["--workers", "0"], "--workers"),
        (["--workers", "x"], "--workers"),
        (["--executor", "dask"], "--executor"),
        (["--config", str(w.work / "missing.yaml")], "missing.yaml"),
        (["--preset", "huge"], "--preset"),
    ]:
        argv, out = gen(*extra)
        cases.append(Case("generate", argv, "error", (needle,), out=out))
    for i, (text, needle) in enumerate(
        [
            ("a: [\n", "not valid YAML"),
            ("- 1\n- 2\n", "mapping"),
            ("seed: abc\n", "seed"),
            ("viewpoints: 3\n", "viewpoints"),
            ("bogus: 1\n", "bogus"),
        ]
    ):
        p = w.work / f"cfg{i}.yaml"
        p.write_text(text)
        argv, out = gen("--config", str(p))
        cases.append(Case("generate", argv, "error", (needle,), out=out))
    cats = w.work / "cats_bad.json"
    cats.write_text("{not json")
    argv, out = gen("--categories", str(cats))
    cases.append(Case("generate", argv, "error", ("cats_bad.json",), out=out))
    argv, out = gen(out=str(w.work / "afile.txt"))
    cases.append(Case("generate", argv, "error", ("afile.txt",), preserve=str(w.work / "afile.txt")))
    argv, out = gen()
    argv[argv.index("--scenes") + 1] = str(w.work / "noscenes")
    cases.append(Case("generate", argv, "error", ("--scenes",), out=out))
    # the existing dataset: the same generation resumes (nothing changes); another one is refused
    same = [
        "dataset",
        "generate",
        "--scenes",
        str(w.scenes),
        "--out",
        str(w.data),
        "--no-progress",
        "--preset",
        "fast",
        "--set",
        "episodes_per_train_scene=12",
        "--set",
        "episodes_per_val_split=16",
        "--set",
        "viewpoints.render_size=48",
        "--set",
        "viewpoints.max_viewpoints=6",
        "--split",
        "val_seen",
    ]
    cases.append(Case("generate-resume", same, "ok", check="unchanged", preserve=str(w.data)))
    for key, val in [("seed", "1"), ("episodes_per_val_split", "17"), ("viewpoints.render_size", "64")]:
        cases.append(Case("generate-resume", same + ["--set", f"{key}={val}"], "error", (key,), preserve=str(w.data)))
    # validate / stats / splits
    for name, d in corrupt_datasets_cached(w).items():
        argv = ["dataset", "validate", str(d), "--scenes", str(w.scenes), "--split", "val_seen"]
        refuse = name in ("not_json", "not_gzip", "deep_json", "wrong_types", "missing_key", "nan_start", "huge_start")
        cases.append(Case("validate", argv, "error" if refuse else "fail1", () if not refuse else ("json.gz",)))
    cases.append(Case("validate", ["dataset", "validate", str(w.data), "--scenes", str(w.scenes)], "ok"))
    for extra, needle in [
        ([str(w.work / "missing"), "--scenes", str(w.scenes)], "DATA"),
        ([str(w.data), "--scenes", str(w.work / "missing")], "--scenes"),
        ([str(w.data), "--scenes", str(w.scenes), "--split", "../x"], "--split"),
        ([str(w.data), "--scenes", str(w.scenes), "--max-episodes-per-scene", "-1"], "--max-episodes"),
    ]:
        cases.append(Case("validate", ["dataset", "validate", *extra], "error", (needle,)))
    cases.append(Case("stats", ["dataset", "stats", str(w.work / "missing")], "error", ("DATA",)))
    cases.append(Case("stats", ["dataset", "stats", str(w.data), "--json"], "ok"))
    bad = corrupt_datasets_cached(w)
    cases.append(
        Case(
            "stats",
            ["dataset", "stats", str(bad["string_geodesic"])],
            "error",
            (".json.gz", "episodes[0]", "geodesic_distance"),
        )
    )
    for i, text in enumerate(['{"train": [1, ', '{"train": 5}', "[1]"]):
        d = w.work / "bad_cats" / f"c{i}"
        if not d.exists():
            shutil.copytree(w.data, d, ignore=shutil.ignore_patterns(".cache"))
        (d / "categories.json").write_text(text)
        cases.append(Case("stats", ["dataset", "stats", str(d)], "error", (str(d / "categories.json"),)))
    # scenes that yield no episode, an empty semantic.txt
    for kind, needle in (("nofloor", "no navigable floor"), ("empty_txt", "semantic.txt")):
        argv, out = gen("--split", "val_seen", "--preset", "fast", "--set", "viewpoints.render_size=48")
        argv[argv.index("--scenes") + 1] = str(broken_world(w, kind))
        cases.append(Case("generate", argv, "error", (needle,), out=out))
    for extra, needle in [
        (["--holdout", "1.5"], "--holdout"),
        (["--holdout", "0"], "--holdout"),
        (["--threshold", "abc"], "--threshold"),
        (["--seed", "-1"], "--seed"),
        (["--out", str(w.work)], "--out"),
        ([], "--vocabulary"),
        (["--vocabulary", "--scenes", str(w.scenes)], "--vocabulary"),
    ]:
        vocab = [] if extra in ([], ["--vocabulary", "--scenes", str(w.scenes)]) else ["--vocabulary"]
        out = [] if "--out" in extra else ["--out", str(w.work / "cats.json")]
        cases.append(Case("splits", ["dataset", "splits", *vocab, *extra, *out], "error", (needle,)))
    return cases


_BAD: dict = {}


def broken_world(w: World, kind: str) -> Path:
    """One val scene of the tiny world, broken: `nofloor` (every face wound the other way, so its floors
    face down) or `empty_txt` (an empty semantic.txt)."""
    root = w.work / f"world_{kind}"
    if root.exists():
        return root
    src = sorted((w.scenes / "val").iterdir())[0]
    dst = root / "val" / src.name
    shutil.copytree(src, dst)
    if kind == "empty_txt":
        next(dst.glob("*.semantic.txt")).write_text("")
        return root
    from ovon.scenes.hm3dsem import write_scene
    from ovon.sim.world import load_scene_any

    scene = load_scene_any(str(dst))
    for mesh in (scene.mesh, scene.semantic_mesh):
        if mesh is not None:
            mesh.faces = mesh.faces[:, [0, 2, 1]].copy()
    shutil.rmtree(dst)
    write_scene(scene, dst)
    return root


def corrupt_datasets_cached(w: World) -> dict[str, Path]:
    if "d" not in _BAD:
        _BAD["d"] = {p.name: p for p in sorted((w.work / "bad").iterdir())}
    return _BAD["d"]


def other_cases(w: World) -> list[Case]:
    """Commands other sessions own: covered too, their results reported per family."""
    cases = []
    t = ["train", "--algo", "dagger", "--preset", "tiny", "--procedural", "0-1"]
    for key, val in [
        ("num_envs", "0"),
        ("rollout_steps", "0"),
        ("lr", "-1"),
        ("total_steps", "abc"),
        ("policy.heads", "3"),
        ("sim.camera.width", "0"),
        ("task.max_steps", "0"),
        ("ppo.clip", "-1"),
        ("dagger.beta_start", "2"),
    ]:
        cases.append(
            Case(
                "train",
                t + ["--set", f"{key}={val}", "--out", str(w.work / "tr" / key)],
                "error",
                (key.split(".")[-1],),
                out=str(w.work / "tr" / key),
            )
        )
    cases.append(
        Case(
            "train",
            t + ["--out", str(w.work / "afile.txt")],
            "error",
            ("afile.txt",),
            preserve=str(w.work / "afile.txt"),
        )
    )
    cases.append(
        Case(
            "train",
            ["train", "--algo", "ppo", "--preset", "tiny", "--procedural", "0-1", "--resume", "--out", str(w.policy)],
            "error",
            ("algo",),
            preserve=str(w.policy),
        )
    )
    cases.append(
        Case(
            "train",
            t + ["--set", "policy.hidden=64", "--resume", "--out", str(w.policy)],
            "error",
            ("hidden",),
            preserve=str(w.policy),
        )
    )
    broken = w.work / "broken_run"
    if not broken.exists():
        shutil.copytree(w.policy, broken)
        ck = broken / "checkpoint.pt"
        ck.write_bytes(ck.read_bytes()[: len(ck.read_bytes()) // 3])
    cases.append(Case("train", t + ["--resume", "--out", str(broken)], "error", ("checkpoint",)))
    torn = w.work / "torn_metrics_run"  # a kill -9 mid-write leaves a torn last line in metrics.jsonl
    if not torn.exists():
        shutil.copytree(w.policy, torn)
        with open(torn / "metrics.jsonl", "ab") as f:
            f.write(b'{"update": 99, "st')
    cases.append(Case("train", t + ["--resume", "--out", str(torn)], "ok", check="metrics", preserve=str(torn)))
    cases.append(
        Case(
            "train",
            [
                "train",
                "--algo",
                "dagger",
                "--preset",
                "tiny",
                "--procedural",
                "x-y",
                "--out",
                str(w.work / "tr" / "proc"),
            ],
            "error",
            ("x-y",),
        )
    )
    for extra, needle in [
        (["--width", "0"], "width"),
        (["--hfov", "180"], "hfov"),
        (["--pose", "1,2"], "--pose"),
        (["--pose", "a,b,c,d"], "--pose"),
        (["--backend", "x"], "--backend"),
        (["--pitch", "1000"], "--pitch"),
        (["--pose", "1e308,0,0,0"], "--pose"),
        (["--seed", "-1"], "--seed"),
        (["--out", str(w.work)], "--out"),
        (["--out", str(w.work / "v.jpg")], ".png"),
    ]:
        out = [] if "--out" in extra else ["--out", str(w.work / "v.png")]
        cases.append(Case("sim", ["sim", "view", "procedural:3", *extra, *out], "error", (needle,)))
    cases.append(
        Case(
            "sim",
            ["sim", "view", str(w.work / "missing.glb"), "--out", str(w.work / "v.png")],
            "error",
            ("missing.glb",),
        )
    )
    cases.append(Case("sim", ["sim", "view", "procedural:x", "--out", str(w.work / "v.png")], "error", ("procedural",)))
    cases.append(Case("sim", ["sim", "bench", "--steps", "-5"], "error", ("--steps",)))
    for extra, needle in [
        (["--split", "train", "--count", "-1"], "--count"),
        (["--split", "nope", "--count", "1"], "--split"),
        (["--split", "train", "--count", "1", "--seed", "-3"], "--seed"),
    ]:
        cases.append(Case("scenes", ["scenes", "generate", *extra, "--out", str(w.work / "sc")], "error", (needle,)))
    cases.append(Case("scenes", ["scenes", "inspect", str(w.work / "missing")], "error", ("missing",)))
    cases.append(
        Case("report", ["report", str(w.work / "missing"), "--out", str(w.work / "rep")], "error", ("missing",))
    )
    cases.append(
        Case(
            "video-after-resume",
            ["video", "--run", str(w.work / "runs" / "shared"), "--episode", "nope", "--out", str(w.work / "v.mp4")],
            "error",
            ("nope",),
        )
    )
    cases.append(
        Case(
            "video",
            ["video", "--run", str(w.work / "missing"), "--episode", "0", "--out", str(w.work / "v.mp4")],
            "error",
            ("missing",),
        )
    )
    cases.append(
        Case(
            "video-after-resume",
            [
                "video",
                "--run",
                str(w.work / "runs" / "shared"),
                "--episode",
                "0",
                "--fps",
                "0",
                "--split",
                "val_seen",
                "--seed",
                "0",
                "--out",
                str(w.work / "v.mp4"),
            ],
            "error",
            ("fps",),
        )
    )
    for argv in (["nope"], ["evaluate"], ["dataset"], ["evaluate", "--bogus"], ["train", "--algo", "x"]):
        cases.append(Case("argparse", argv, "error", ()))
    return cases


# ----------------------------------------------------------------------------------------------------
# running and judging


def snapshot(path: str) -> dict[str, bytes]:
    p = Path(path)
    if p.is_file():
        return {p.name: p.read_bytes()}
    if not p.is_dir():
        return {}
    out = {}
    for f in p.rglob("*"):
        if f.is_file() and ".cache" not in f.parts:
            out[str(f.relative_to(p))] = f.read_bytes()
    return out


def complete_records(snap: dict[str, bytes]) -> set[str]:
    return {ln for ln in snap.get("episodes.jsonl", b"").decode().splitlines() if ln.strip()}


def judge(case: Case, rc: int | None, stderr: str, before: dict[str, bytes]) -> tuple[str, str]:
    errors = [ln for ln in stderr.strip().splitlines() if ln.strip() and not ln.startswith("ovon: warning:")]
    line = errors[0] if errors else ""
    if rc is None:
        return "hang", f"over {TIMEOUT_S} s"
    if "Traceback" in stderr or "internal error" in stderr:
        return "traceback", (stderr.strip().splitlines() or [""])[-1][:300]
    if case.preserve:
        after = snapshot(case.preserve)
        if Path(case.preserve).name == "episodes" or case.check == "unchanged":
            lost = [k for k in before if k not in after and not k.endswith("generation_report.json")]
            if lost:
                return "data_loss", f"files gone: {lost[:3]}"
        if not complete_records(before) <= complete_records(after):
            return "data_loss", "complete records gone"
        if Path(case.preserve).is_file() and before != after:
            return "data_loss", "file overwritten"
    if case.expect == "error":
        if rc == 0:
            return "silent_wrong", "exit 0 where an error was due"
        if len(errors) != 1 or "error:" not in line:
            return "vague_error", f"{len(errors)} error lines: {' | '.join(errors)[:300]}"
        missing = [n for n in case.needles if n not in line]
        if missing:
            return "vague_error", f"does not name {missing}: {line[:300]}"
        if case.out and Path(case.out).exists() and not before:
            return "silent_wrong", f"refused but left {case.out}"
        return "clear_error", line[:300]
    if case.expect == "fail1":
        if rc == 1 and "problem(s)" in (stderr + _STDOUT.get(id(case), "")):
            return "right_result", "validate failed and listed the problems"
        return "silent_wrong", f"validate exit {rc}"
    if rc != 0:
        return "silent_wrong" if not line else "vague_error", f"exit {rc}: {line[:300]}"
    why = check_output(case, before)
    return ("right_result", "outputs check out") if not why else ("silent_wrong", why)


_STDOUT: dict[int, str] = {}


def check_output(case: Case, before: dict[str, bytes]) -> str:
    if case.check == "unchanged":
        after = snapshot(case.preserve)
        changed = [
            k
            for k in set(before) | set(after)
            if before.get(k) != after.get(k) and not k.endswith("generation_report.json")
        ]
        return f"changed: {changed[:4]}" if changed else ""
    if case.check == "metrics":
        try:
            rows = [json.loads(x) for x in (Path(case.preserve) / "metrics.jsonl").read_text().splitlines()]
        except ValueError as e:
            return f"metrics.jsonl still holds a torn line after the resume ({e})"
        return "" if rows and all(isinstance(r, dict) for r in rows) else "metrics.jsonl lost its rows"
    if case.check in ("counts", "skipped"):
        out = Path(case.out or case.preserve)
        summary = json.loads((out / "summary.json").read_text())
        recs = [json.loads(x) for x in (out / "episodes.jsonl").read_text().splitlines()]
        keys = {(r["split"], r["seed"], r["scene"], r["episode_id"]) for r in recs}
        if len(keys) != len(recs):
            return "duplicate records"
        argv = case.argv
        splits = (
            argv[argv.index("--splits") + 1].split(",")
            if "--splits" in argv
            else ["val_seen", "val_seen_synonyms", "val_unseen"]
        )
        seeds = [s for s in argv[argv.index("--seeds") + 1].split(",") if s.strip()] if "--seeds" in argv else ["0"]
        ep = int(float(argv[argv.index("--episodes") + 1])) if "--episodes" in argv else 10**9
        data = argv[argv.index("--data") + 1]
        sys.path.insert(0, str(ROOT))
        import warnings

        from ovon.dataset.episodes import load_specs

        for split in splits:
            name = {"val_unseen_hard": "val_unseen"}.get(split, split)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                avail = len(load_specs(data, argv[argv.index("--scenes") + 1], split, None))
            want = min(ep, avail) * len(seeds)
            if case.check == "skipped" and name == "val_seen" and "off_map" in data:
                want -= len(seeds)  # the start off the map is skipped before the run, the others run
            entry = summary["splits"].get(split, summary["splits"].get(name, {}))
            got = entry.get("episodes")
            if got != want:
                return f"{split}: {got} episodes in the summary, expected {want}"
            sk = entry.get("skipped") or {}
            if sk.get("picked", -1) - sk.get("count", 0) != got // len(seeds):
                return f"{split}: summary's skipped {sk} does not add up to {got} episodes over {len(seeds)} seed(s)"
            if case.check == "skipped" and not sk.get("count"):
                return f"{split}: the skipped episode is not counted in summary.json"
        return ""
    return ""


def run_case(case: Case) -> Case:
    before = snapshot(case.preserve) if case.preserve else {}
    if case.out and not case.preserve:
        before = snapshot(case.out)
    t0 = time.time()
    try:
        res = subprocess.run(
            ovon_cmd(case.argv), env=env(), cwd=ROOT, capture_output=True, text=True, timeout=TIMEOUT_S
        )
        rc, err = res.returncode, res.stderr
        _STDOUT[id(case)] = res.stdout
    except subprocess.TimeoutExpired:
        rc, err = None, ""
    case.seconds = round(time.time() - t0, 2)
    case.outcome, case.detail = judge(case, rc, err, before)
    return case


# ----------------------------------------------------------------------------------------------------
# kill -9 rounds


def _children_alive(pids: list[int]) -> list[int]:
    alive = []
    for p in pids:
        try:
            state = Path(f"/proc/{p}/stat").read_text().split(")")[-1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.append(p)
    return alive


def _progress(kind: str, out: Path) -> int:
    """Work done so far: records written (evaluate), goal caches + shards written (generate)."""
    if kind == "evaluate":
        f = out / "episodes.jsonl"
        return f.read_bytes().count(b"\n") if f.exists() else 0
    return len(list(out.glob(".cache/goals/*.json.gz"))) + len(list(out.glob("*/content/*.json.gz")))


def kill_round(kind: str, w: World, rnd: random.Random, index: int) -> Case:
    """Kill the main process 1-3 times, each at a random moment: after a random time, or once a random
    amount of work is on disk (so kills land before, during and near the end of the work)."""
    if kind == "evaluate":
        args = [
            "evaluate",
            "--agent",
            "frontier",
            "--data",
            str(w.data),
            "--scenes",
            str(w.scenes),
            "--splits",
            "val_seen,val_unseen",
            "--seeds",
            "0,1",
            "--workers",
            "2",
            "--no-progress",
        ]
        ref, files = w.work / "kill" / "eval_ref", ("episodes.jsonl", "summary.json", "table.md", "run_identity.json")
    else:
        args = [
            "dataset",
            "generate",
            "--scenes",
            str(w.scenes),
            "--preset",
            "fast",
            "--split",
            "val_seen",
            "--split",
            "val_unseen",
            "--set",
            "episodes_per_val_split=10",
            "--set",
            "viewpoints.render_size=48",
            "--set",
            "viewpoints.max_viewpoints=4",
            "--workers",
            "2",
            "--no-progress",
        ]
        ref, files = w.work / "kill" / "gen_ref", None
    if not ref.exists():
        subprocess.run(ovon_cmd([*args, "--out", str(ref)]), env=env(), cwd=ROOT, check=True, capture_output=True)
    total = _progress(kind, ref)
    out = w.work / "kill" / f"{kind}{index}"
    shutil.rmtree(out, ignore_errors=True)
    case = Case(f"kill-{kind}", [*args, "--out", str(out)], "ok")
    children: list[int] = []
    progress = []
    t0 = time.time()
    for _ in range(rnd.randint(1, 3)):
        by_time = rnd.random() < 0.3
        when = rnd.uniform(1.0, 12.0) if by_time else rnd.randint(1, max(1, total - 1))
        p = subprocess.Popen(
            ovon_cmd(case.argv), env=env(), cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        start = time.time()
        while p.poll() is None and (time.time() - start < when if by_time else _progress(kind, out) < when):
            time.sleep(0.02)
        before = complete_records(snapshot(str(out)))
        children += [
            int(x) for x in subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True, text=True).stdout.split()
        ]
        p.send_signal(signal.SIGKILL)
        p.wait()
        after = complete_records(snapshot(str(out)))
        progress.append(
            f"kill at {time.time() - start:.1f}s with {_progress(kind, out)}/{total} "
            f"{'records' if kind == 'evaluate' else 'goal caches + shards'} done"
        )
        if not before <= after:
            case.outcome, case.detail = "data_loss", "records lost at the kill"
            return case
    time.sleep(3)
    orphans = _children_alive(children)
    res = subprocess.run(ovon_cmd(case.argv), env=env(), cwd=ROOT, capture_output=True, text=True, timeout=1200)
    case.seconds = round(time.time() - t0, 1)
    if orphans:
        case.outcome, case.detail = "hang", f"orphan workers {orphans}"
    elif res.returncode != 0:
        case.outcome, case.detail = "traceback" if "Traceback" in res.stderr else "vague_error", res.stderr[-300:]
    else:
        a, b = snapshot(str(out)), snapshot(str(ref))
        names = files or [k for k in b if not k.endswith("generation_report.json")]
        diff = [k for k in names if a.get(k) != b.get(k)]
        extra = [k for k in a if k not in b and not k.endswith(("generation_report.json", ".rejected.jsonl"))]
        if diff or extra:
            case.outcome, case.detail = "silent_wrong", f"differs from the uninterrupted run: {(diff + extra)[:4]}"
        else:
            case.outcome = "right_result"
            case.detail = f"byte-identical to the uninterrupted run; no orphans; {'; '.join(progress)}"
    return case


# ----------------------------------------------------------------------------------------------------


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="JSON report path")
    ap.add_argument("--work", default="/tmp/ovon_cli_campaign", help="scratch folder (tiny world, runs)")
    ap.add_argument("--seed", type=int, default=13)
    ap.add_argument("--jobs", type=int, default=2, help="cases run at once")
    ap.add_argument("--kills", type=int, default=4, help="kill rounds per command (evaluate, dataset generate)")
    ap.add_argument("--only", help="run only the case families whose name starts with this")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    for sub in ("runs", "gen", "tr"):
        shutil.rmtree(work / sub, ignore_errors=True)
    rnd = random.Random(args.seed)
    t0 = time.time()
    w = build_world(work)
    cases = evaluate_cases(w, rnd) + dataset_cases(w) + other_cases(w)
    if args.only:
        cases = [c for c in cases if c.family.startswith(args.only)]
    # Cases on one shared folder run alone and in order (a concurrent one would be refused by the lock).
    sequential = ("resume", "generate-resume", "video-after-resume")
    ordered = sorted((c for c in cases if c.family in sequential), key=lambda c: sequential.index(c.family))
    free = [c for c in cases if c.family not in sequential]
    with ThreadPoolExecutor(args.jobs) as pool:
        done = list(pool.map(run_case, free))
    done += [run_case(c) for c in ordered]
    if not args.only or args.only.startswith("kill"):
        for i in range(args.kills):
            done.append(kill_round("evaluate", w, rnd, i))
            done.append(kill_round("generate", w, rnd, i))
    counts = Counter(c.outcome for c in done)
    by_family: dict[str, Counter] = {}
    for c in done:
        by_family.setdefault(c.family, Counter())[c.outcome] += 1
    report = {
        "cases": len(done),
        "counts": dict(counts),
        "by_family": {k: dict(v) for k, v in by_family.items()},
        "seconds": round(time.time() - t0, 1),
        "results": [asdict(c) for c in done],
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(report, indent=1))
    print(f"{'family':18s} " + " ".join(f"{k:>13s}" for k in ("clear_error", "right_result", *BAD)))
    for fam, cnt in sorted(by_family.items()):
        print(f"{fam:18s} " + " ".join(f"{cnt.get(k, 0):13d}" for k in ("clear_error", "right_result", *BAD)))
    print(f"{'total':18s} " + " ".join(f"{counts.get(k, 0):13d}" for k in ("clear_error", "right_result", *BAD)))
    for c in done:
        if c.outcome in BAD:
            print(f"  {c.outcome}: {c.family}: {' '.join(c.argv)[:160]}\n      {c.detail[:300]}")
    print(f"{len(done)} cases in {report['seconds']} s; report: {args.out}")
    return 0 if not any(counts.get(k) for k in BAD) else 1


if __name__ == "__main__":
    sys.exit(main())
