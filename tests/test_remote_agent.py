"""`ovon serve` + `ovon evaluate --agent remote:HOST:PORT`: byte-identical results to the same agent
in-process (random, an oracle reading the privileged channel, VLFM), batching over workers and streams,
one-line errors, and a server that dies or hangs mid-run, then a re-run that resumes. Servers listen on
loopback, on ports they picked themselves (port 0) unless a test needs a given one, and are always stopped."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
from ovon_agent import RemoteError

from ovon.agents.remote import RemoteConfig
from ovon.agents.served import servable_factory, served_config
from ovon.cli.main import main as ovon
from ovon.evaluate.config import EvalConfig
from ovon.evaluate.harness import evaluate
from ovon.evaluate.results import read_records
from ovon.runfolder import RunFolderError
from tests.remote_agents import BatchedRandom, free_ports, serving

ROOT = Path(__file__).resolve().parents[1]
OUTPUTS = ("episodes.jsonl", "summary.json")


def cfg_for(tiny_dataset, tiny_scenes, agent: str, **kw) -> EvalConfig:
    kw.setdefault("splits", ("val_seen", "val_unseen"))
    kw.setdefault("episodes", 3)
    return EvalConfig(agent=agent, data=str(tiny_dataset), scenes=str(tiny_scenes), **kw)


def same_files(a: Path, b: Path) -> None:
    """Byte-identical results; the protocol cards agree but for what each says of its agent (a served agent
    is a black box: its card says what the run allowed it, not what it is)."""
    for name in OUTPUTS:
        if name != "summary.json":
            assert (a / name).read_bytes() == (b / name).read_bytes(), name
            continue
        sa, sb = (json.loads((d / name).read_text()) for d in (a, b))
        agents = [s.get("protocol", {}).pop("agent", None) for s in (sa, sb)]
        assert sa == sb, name
        assert agents[1] is None or (agents[1]["description"], agents[1]["oracle_perception"]) == ("served agent", None)


@contextmanager
def serve_process(*args: str, env: dict | None = None):
    """`ovon serve ARGS --port 0` in its own process (the repository root as working directory), killed on
    exit; yields the port it listens on, read from the line it prints (the server binds a free port itself,
    so no other process can take it between the pick and the bind)."""
    cmd = [sys.executable, "-m", "ovon.cli.main", "serve", *args, "--port", "0"]
    with tempfile.TemporaryFile("w+") as err:  # a file, not a pipe: the server's log never blocks it
        proc = subprocess.Popen(
            cmd,
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=err,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})},
            start_new_session=True,
        )
        try:
            line = proc.stdout.readline()
            bound = re.search(r"remote:127\.0\.0\.1:(\d+)", line)
            if not bound:
                proc.wait()
                err.seek(0)
                raise AssertionError(f"`ovon serve` did not start: {line!r}\n{err.read()[-3000:]}")
            yield int(bound.group(1))
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            proc.stdout.close()


def test_served_random_agent_gives_byte_identical_files(tiny_dataset, tiny_scenes, tmp_path):
    evaluate(cfg_for(tiny_dataset, tiny_scenes, "random"), tmp_path / "local", progress=False)
    with serving(servable_factory("random"), name="random") as server:
        remote = cfg_for(tiny_dataset, tiny_scenes, f"remote:127.0.0.1:{server.port}")
        evaluate(remote, tmp_path / "remote", progress=False)
    same_files(tmp_path / "local", tmp_path / "remote")
    assert (tmp_path / "remote" / "table.md").read_text() == (tmp_path / "local" / "table.md").read_text()


def test_workers_and_lockstep_streams_reach_act_batch_as_batches(tiny_dataset, tiny_scenes, tmp_path):
    """Two worker processes (two connections) x 3 episodes in lockstep each: one agent object with
    act_batch sees batches, keeps episodes apart by stream, and the files are those of the random agent."""
    evaluate(cfg_for(tiny_dataset, tiny_scenes, "random"), tmp_path / "local", progress=False)
    agent = BatchedRandom()
    with serving(agent, name="random") as server:
        remote = cfg_for(
            tiny_dataset, tiny_scenes, f"remote:127.0.0.1:{server.port}", workers=2, remote=RemoteConfig(batch=3)
        )
        evaluate(remote, tmp_path / "remote", progress=False)
        deadline = time.monotonic() + 10
        while server._sessions and time.monotonic() < deadline:  # workers said goodbye as they ended
            time.sleep(0.05)
        assert not server._sessions
    same_files(tmp_path / "local", tmp_path / "remote")
    assert max(agent.batch_sizes) >= 3
    assert len({k.split("/")[0] for k in agent.agents}) >= 2  # several connections (workers)


def test_the_privileged_channel_travels_only_when_the_run_allows_oracles(tiny_dataset, tiny_scenes, tmp_path, capsys):
    agent = "tests.remote_agents:OracleProbe"
    evaluate(cfg_for(tiny_dataset, tiny_scenes, agent), tmp_path / "local", progress=False)
    with serving(servable_factory(agent), name=agent, observations=["depth", "goal"]) as server:
        address = f"remote:127.0.0.1:{server.port}"
        rc = ovon(
            [
                "evaluate",
                "--agent",
                address,
                "--data",
                str(tiny_dataset),
                "--scenes",
                str(tiny_scenes),
                "--episodes",
                "3",
                "--out",
                str(tmp_path / "refused"),
            ]
        )
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and "asks for the privileged channel" in err
        assert "--set remote.allow_privileged=true" in err and not (tmp_path / "refused").exists()
        remote = cfg_for(tiny_dataset, tiny_scenes, address, remote=RemoteConfig(allow_privileged=True))
        evaluate(remote, tmp_path / "remote", progress=False)
    same_files(tmp_path / "local", tmp_path / "remote")


def test_a_server_that_dies_is_one_line_and_the_rerun_resumes(tiny_dataset, tiny_scenes, tmp_path):
    cfg = cfg_for(tiny_dataset, tiny_scenes, "random", chunk=1)
    evaluate(cfg, tmp_path / "local", progress=False)
    out = tmp_path / "remote"
    serve = ("tests.remote_agents:DieAt", "--name", "random")
    with serve_process(*serve, env={"OVON_TEST_DIE_AT": "3"}) as port:
        remote = dataclasses.replace(cfg, agent=f"remote:127.0.0.1:{port}")
        with pytest.raises(RemoteError) as e:
            evaluate(remote, out, progress=False)
    msg = str(e.value)
    assert f"tcp://127.0.0.1:{port} closed the connection" in msg and "step 1 of episode val_" in msg
    assert "re-run the same command to resume" in msg and "\n" not in msg
    assert len(read_records(out)) == 2  # the episodes finished before the crash are kept
    with serve_process(*serve) as again:  # any address: the run's identity is what the agent says it is
        evaluate(dataclasses.replace(cfg, agent=f"remote:127.0.0.1:{again}"), out, progress=False)
    same_files(tmp_path / "local", out)


def test_a_served_agent_continues_its_run_folder_from_another_address(tiny_dataset, tiny_scenes, tmp_path):
    """A run folder of a served agent is identified by what the agent says it is (its handshake name and
    config), not by where it is served: the same agent on another port extends the run; the same name with
    other arguments, or the agent in-process, is refused."""
    evaluate(cfg_for(tiny_dataset, tiny_scenes, "random"), tmp_path / "local", progress=False)
    out = tmp_path / "remote"
    same = {"name": "random", "config": served_config("random")}
    with serving(servable_factory("random"), **same) as first, serving(servable_factory("random"), **same) as second:
        assert first.port != second.port
        evaluate(cfg_for(tiny_dataset, tiny_scenes, f"remote:127.0.0.1:{first.port}", episodes=2), out, progress=False)
        evaluate(cfg_for(tiny_dataset, tiny_scenes, f"remote:127.0.0.1:{second.port}"), out, progress=False)
    same_files(tmp_path / "local", out)
    kwargs = {"stop_probability": 0.5}
    other = {"name": "random", "config": served_config("random", kwargs)}
    with serving(servable_factory("random", kwargs), **other) as third:
        with pytest.raises(RunFolderError, match=r"settings differ: served_agent\.config_keys .*stop_probability"):
            evaluate(cfg_for(tiny_dataset, tiny_scenes, f"remote:127.0.0.1:{third.port}"), out, progress=False)
    with pytest.raises(RunFolderError, match='settings differ: agent "remote" -> "random"'):
        evaluate(cfg_for(tiny_dataset, tiny_scenes, "random"), out, progress=False)


def test_a_hung_agent_times_out_with_the_episode_named(tiny_dataset, tiny_scenes, tmp_path):
    release = threading.Event()

    class Hung:
        def reset(self, episode_info: dict) -> None:
            pass

        def act(self, observation: dict) -> int:
            release.wait(30)
            return 0

    with serving(Hung) as server:
        cfg = cfg_for(tiny_dataset, tiny_scenes, f"remote:127.0.0.1:{server.port}", remote=RemoteConfig(timeout_s=2.0))
        try:
            with pytest.raises(
                RemoteError,
                match=r"did not answer step 1 of episode val_seen/\S+/\S+ within 2 s: "
                r"no answer; fix: .*--set remote.timeout_s.*resume",
            ):
                evaluate(cfg, tmp_path / "hung", progress=False)
        finally:
            release.set()


def test_command_line_refusals_are_one_line(tiny_dataset, tiny_scenes, tmp_path, capsys):
    [port] = free_ports(1)  # nothing listens there
    data = ["--data", str(tiny_dataset), "--scenes", str(tiny_scenes), "--out", str(tmp_path / "x")]
    cases = [
        (["evaluate", "--agent", "remote:localhost", *data], "is not remote:HOST:PORT"),
        (["evaluate", "--agent", "remote:127.0.0.1:70000", *data], "PORT in 1..65535"),
        (
            ["evaluate", "--agent", f"remote:127.0.0.1:{port}", "--agent-arg", "seed=3", *data],
            "belong to the server; fix: pass them to `ovon serve AGENT --agent-arg seed=...`",
        ),
        (
            ["evaluate", "--agent", f"remote:127.0.0.1:{port}", "--set", "remote.timeout_s=0.3", *data],
            f"tcp://127.0.0.1:{port} did not answer the handshake within 0.3 s: nothing is listening there",
        ),
        (["evaluate", "--agent", f"remote:127.0.0.1:{port}", "--set", "remote.batch=0", *data], "remote.batch"),
        (["serve", "shortest-path"], "cannot be served: it plans on the navigation grid"),
        (["serve", "no_such_agent"], "unknown agent 'no_such_agent'"),
        (["serve", "random", "--agent-arg", "bogus=1"], "has no constructor argument 'bogus'"),
        (["serve", "random", "--observations", "rgb,sonar"], "--observations 'rgb,sonar': expected"),
        (["serve", "random", "--port", "99999"], "--port"),
    ]
    for argv, expected in cases:
        rc = ovon(argv)
        err = capsys.readouterr().err
        assert rc == 2 and err.startswith("ovon: error: ") and err.count("\n") == 1, (argv, err)
        assert expected in err, (argv, err)
    with serving(servable_factory("random")) as server:  # the port is taken
        rc = ovon(["serve", "random", "--port", str(server.port)])
        err = capsys.readouterr().err
        assert rc == 2 and f"--port {server.port}: cannot listen" in err and "fix: another --port" in err
    assert not (tmp_path / "x").exists()


def test_the_token_comes_from_the_environment(tiny_dataset, tiny_scenes, tmp_path, monkeypatch):
    with serving(servable_factory("random"), name="random", token="t0k") as server:
        cfg = cfg_for(tiny_dataset, tiny_scenes, f"remote:127.0.0.1:{server.port}", episodes=1)
        monkeypatch.delenv("OVON_REMOTE_TOKEN", raising=False)
        with pytest.raises(RemoteError, match="wrong or missing token; fix: set OVON_REMOTE_TOKEN"):
            evaluate(cfg, tmp_path / "no", progress=False)
        monkeypatch.setenv("OVON_REMOTE_TOKEN", "t0k")
        assert evaluate(cfg, tmp_path / "yes", progress=False)["name"] == "random"
    assert "t0k" not in (tmp_path / "yes" / "run.json").read_text()


def test_served_vlfm_gives_byte_identical_files(tiny_dataset, tiny_scenes, tmp_path):
    """VLFM (oracle detection, oracle-vl value: ground truth travels) served without RGB (the evaluation
    skips colour rendering) gives the files of VLFM in-process."""
    cfg = cfg_for(tiny_dataset, tiny_scenes, "vlfm", splits=("val_seen", "val_seen_synonyms"), episodes=2)
    evaluate(cfg, tmp_path / "local", progress=False)
    wanted = ["depth", "odometry", "goal", "collided"]
    with serving(servable_factory("vlfm"), name="vlfm", observations=wanted) as server:
        remote = dataclasses.replace(
            cfg, agent=f"remote:127.0.0.1:{server.port}", remote=RemoteConfig(allow_privileged=True)
        )
        evaluate(remote, tmp_path / "remote", progress=False)
    same_files(tmp_path / "local", tmp_path / "remote")


def test_make_agent_gives_a_connected_client():
    import numpy as np

    from ovon.agents import make_agent
    from ovon.agents.random_agent import RandomAgent
    from ovon.config.base import ConfigError

    obs = {"depth": np.ones((4, 4), np.float32), "odometry": np.zeros(3, np.float32), "goal": "bed", "collided": 0}
    info = {"episode_id": "7", "seed": 3, "goal": "bed"}
    with serving(servable_factory("random"), name="random") as server:
        with pytest.raises(ConfigError, match="timeout_s"):
            make_agent(f"remote:127.0.0.1:{server.port}", timeout_s=-1)
        remote = make_agent(f"remote:127.0.0.1:{server.port}", timeout_s=5)
        local = RandomAgent()
        try:
            assert remote.name == "random" and remote.privileged is False
            for agent in (remote, local):
                agent.reset(info)
            assert [remote.act(obs) for _ in range(30)] == [local.act(obs) for _ in range(30)]
        finally:
            remote.close()


def test_a_handshake_config_that_is_not_plain_values_is_one_line():
    from ovon.agents.remote import check_remote
    from ovon.config.base import ConfigError

    with serving(servable_factory("random"), name="random", config={"weights": b"\x00"}) as server:
        with pytest.raises(ConfigError, match=r"answered the handshake with config .*expected a map of JSON values"):
            check_remote(f"remote:127.0.0.1:{server.port}", RemoteConfig(timeout_s=5))
    with pytest.raises(TypeError, match="config must be a dict"):
        serving(servable_factory("random"), config=["x"]).__enter__()
