"""Bad input through the Python API and the remote-agent client (audit defects 7-14): each is one line
naming the key or argument, the value, what is expected and the fix, before any work, and nothing is
written. Fake servers listen on loopback, on free ports, and are always stopped."""

from __future__ import annotations

import dataclasses
import math
import socket
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgpack
import numpy as np
import pytest
import zmq
from ovon_agent import Client, RemoteError

from ovon.agents.remote import RemoteAgent, RemoteConfig, check_remote, parse_address
from ovon.config.base import ConfigError, from_dict, validate
from ovon.evaluate.config import EvalConfig
from tests.cli_errors import one_line, run
from tests.remote_agents import serving


@pytest.fixture
def roots(tmp_path: Path) -> list[str]:
    """--data / --scenes that exist (the refusals below come before any episode is read) and an --out."""
    (tmp_path / "data").mkdir()
    (tmp_path / "scenes").mkdir()
    return ["--data", str(tmp_path / "data"), "--scenes", str(tmp_path / "scenes"), "--out", str(tmp_path / "out")]


# -- 7: configs built in Python --------------------------------------------------------------------------
def test_a_path_object_is_accepted_where_from_dict_accepts_it_and_stored_as_str(tmp_path: Path) -> None:
    cfg = validate(EvalConfig(data=tmp_path, scenes=tmp_path))
    assert cfg.data == str(tmp_path) and isinstance(cfg.data, str) and isinstance(cfg.scenes, str)
    assert from_dict(EvalConfig, {"data": tmp_path, "scenes": tmp_path}) == cfg
    with pytest.raises(ConfigError, match=r"^--data = PosixPath\('.*nowhere'\): expected an existing folder"):
        validate(EvalConfig(data=tmp_path / "nowhere", scenes=tmp_path))


def test_a_mapping_for_a_nested_config_is_named_as_a_mapping(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as e:
        validate(EvalConfig(data=str(tmp_path), scenes=str(tmp_path), sim={"camera": {"width": 64}}))
    msg = str(e.value)
    assert msg.startswith("sim = {'camera': {'width': 64}}: expected a SimConfig, got a dict; fix: pass SimConfig(")
    assert "from_dict(EvalConfig" in msg and "\n" not in msg and "a mapping of" not in msg


@pytest.mark.parametrize("data", [{1: 2}, {"sim": {2: 3}}, {("a",): 1}])
def test_keys_that_are_not_strings_are_one_line(data: dict) -> None:
    with pytest.raises(ConfigError, match=r"config key .* is not a name; valid keys.*; fix: use those names"):
        from_dict(EvalConfig, data)


# -- 8: train() validates what it is given before writing anything ------------------------------------------
def _tiny(**changes: Any):
    from ovon.train import train_preset

    return train_preset("tiny", **changes)


@pytest.mark.parametrize(
    ("changes", "source", "needle"),
    [
        ({"num_envs": 0}, {"procedural": "0"}, "num_envs = 0: expected an integer > 0"),
        ({"lr": -1.0}, {"procedural": "0"}, "lr = -1.0: expected a number >= 0"),
        ({"device": "tpu"}, {"procedural": "0"}, "device = 'tpu': expected auto, cpu"),
        (
            {"algo": "ppo", "num_envs": 2, "ppo.minibatches": 4},
            {"procedural": "0"},
            "ppo.minibatches = 4, num_envs = 2: expected ppo.minibatches <= num_envs for algo ppo",
        ),
        (
            {"algo": "ppo", "learn_dtype": "bfloat16"},
            {"procedural": "0"},
            "learn_dtype = 'bfloat16', algo = 'ppo': expected learn_dtype float32 for algo ppo",
        ),
        ({"learn_dtype": "float16"}, {"procedural": "0"}, "learn_dtype = 'float16': expected"),
        ({}, {"procedural": "0", "limit": -1}, "EpisodeSource(limit=-1): expected an integer > 0"),
        ({}, {"procedural": "0", "limit": 0}, "EpisodeSource(limit=0)"),
        ({}, {"procedural": "0", "task": "imagenav"}, "EpisodeSource(task='imagenav')"),
    ],
)
def test_train_refuses_a_bad_config_or_source_before_writing(
    tmp_path: Path, changes: dict, source: dict, needle: str
) -> None:
    from ovon.train import EpisodeSource, train
    from ovon.train.config import PPOConfig

    changes = dict(changes)
    if "ppo.minibatches" in changes:
        changes["ppo"] = PPOConfig(minibatches=changes.pop("ppo.minibatches"))
    out = tmp_path / "run"
    with pytest.raises(ConfigError) as e:
        train(_tiny(**changes), EpisodeSource(**source), out)
    assert needle in str(e.value) and "fix:" in str(e.value) and "\n" not in str(e.value)
    assert not out.exists()  # no config.json, run_identity.json or text_cache.pt: the fixed call may run there


def test_train_preset_changes_are_checked_by_train(tmp_path: Path) -> None:
    from ovon.train import train

    with pytest.raises(ConfigError, match="num_envs = 0"):
        train(_tiny(num_envs=0), None, tmp_path / "run")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"out_dir": None}, "train(out_dir=None): expected the path of a run folder"),
        ({"out_dir": ""}, "out_dir is empty"),
        ({"specs": "data/datasets/ovon"}, "expected a list of EpisodeSpec, an EpisodeSource or None"),
        ({"specs": [1, 2]}, "item 0 is a int, not an EpisodeSpec"),
        ({"cfg": {"algo": "bc"}}, "train(cfg=dict): expected a TrainConfig"),
        ({"resume": "yes"}, "train(resume='yes'): expected True or False"),
        ({"init": 5}, "train(init=5): expected the path of a policy.pt"),
    ],
)
def test_train_refuses_bad_arguments(tmp_path: Path, monkeypatch, kwargs: dict, needle: str) -> None:
    from ovon.train import EpisodeSource, train

    monkeypatch.chdir(tmp_path)
    call = {"cfg": _tiny(), "specs": EpisodeSource(procedural="0"), "out_dir": tmp_path / "run", **kwargs}
    with pytest.raises(ConfigError) as e:
        train(**call)
    assert needle in str(e.value) and "fix:" in str(e.value)
    assert list(tmp_path.iterdir()) == []  # no folder named None, no run folder


def test_the_ppo_minibatch_rule_binds_ppo_only() -> None:
    """A DAgger run with one env is not refused for a PPO setting it never uses; its PPO fields keep their
    domains, and a PPO run gets the rule."""
    from ovon.train import check_config
    from ovon.train.config import PPOConfig

    cfg = check_config(_tiny(algo="dagger", num_envs=1))
    assert cfg.num_envs == 1 and cfg.ppo.minibatches == 2
    with pytest.raises(ConfigError, match="ppo.minibatches = 0: expected an integer > 0"):
        check_config(_tiny(algo="dagger", num_envs=1, ppo=PPOConfig(minibatches=0)))
    with pytest.raises(ConfigError, match="ppo.minibatches <= num_envs"):
        check_config(_tiny(algo="ppo", num_envs=1))
    assert check_config(_tiny(algo="ppo", lr=0.0)).lr == 0.0  # a frozen policy: a diagnostic that always ran


def test_the_cli_and_python_accept_the_same_train_configs(tmp_path) -> None:
    """The exceptions `train()` once made by hand (lr 0; DAgger with ppo.minibatches > num_envs) are the
    config's own domain and rule, so `ovon train --set` accepts them too, and rejects lr < 0 in one line."""
    from types import SimpleNamespace

    from ovon.train.config import build_config

    def cli(algo: str, *sets: str):
        return build_config(
            SimpleNamespace(
                algo=algo, expert=None, task=None, preset="tiny", policy=None, encoder=None, config=None, set=list(sets)
            )
        )

    cfg = cli("dagger", "lr=0", "num_envs=1")
    assert cfg.lr == 0.0 and cfg.num_envs == 1 and cfg.ppo.minibatches == 2
    with pytest.raises(ConfigError, match=r"ppo.minibatches <= num_envs for algo ppo"):
        cli("ppo", "num_envs=1")
    with pytest.raises(ConfigError, match=r"lr = -0.5: expected a number >= 0"):
        cli("dagger", "lr=-0.5")


# -- 9: the experts' keyword arguments have their declared domains ------------------------------------------
@pytest.mark.parametrize(
    ("agent", "kwargs", "needle"),
    [
        ("frontier", {"no_frontier_behaviour": "fly"}, "--agent-arg no_frontier_behaviour = 'fly': expected one of"),
        ("frontier", {"stop_margin_m": "x"}, "--agent-arg stop_margin_m = 'x': expected a number >= 0"),
        ("frontier", {"lookahead_m": -1}, "--agent-arg lookahead_m = -1.0: expected a number > 0"),
        ("shortest-path", {"lookahead_m": 0}, "--agent-arg lookahead_m = 0.0: expected a number > 0"),
        ("shortest-path", {"lookahed_m": 1}, "--agent-arg lookahed_m (did you mean 'lookahead_m'?)"),
    ],
)
def test_expert_agent_arguments_are_checked(agent: str, kwargs: dict, needle: str) -> None:
    from ovon.agents import load_agent_class

    with pytest.raises(ConfigError) as e:
        load_agent_class(agent)(**kwargs)
    assert needle in str(e.value) and "\n" not in str(e.value)
    assert load_agent_class(agent)(stop_margin_m=0.1).cfg.stop_margin_m == 0.1


@pytest.mark.parametrize("arg", ["no_frontier_behaviour=fly", "stop_margin_m=x", "lookahead_m=-1"])
def test_expert_agent_arguments_on_the_command_line(roots: list[str], tmp_path: Path, capsys, arg: str) -> None:
    rc, _, errors = run(["evaluate", "--agent", "frontier", "--agent-arg", arg, *roots], capsys)
    one_line(rc, errors, f"--agent-arg {arg.partition('=')[0]}")
    assert not (tmp_path / "out").exists()


# -- 10: the policy agent's temperature and deterministic ---------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"temperature": math.nan}, "--agent-arg temperature = nan: expected a number > 0"),
        ({"temperature": math.inf}, "--agent-arg temperature = inf"),
        ({"temperature": 0.0}, "--agent-arg temperature = 0.0"),
        ({"deterministic": "no"}, "--agent-arg deterministic = 'no': expected true or false"),
        ({"device": "tpu"}, "--agent-arg device = 'tpu'"),
        ({"threads": 1.5}, "--agent-arg threads = 1.5"),
    ],
)
def test_policy_agent_arguments_are_checked_before_the_checkpoint(tmp_path: Path, kwargs: dict, needle: str) -> None:
    from ovon.agents.policy_agent import PolicyAgent

    with pytest.raises(ConfigError) as e:
        PolicyAgent(str(tmp_path / "missing.pt"), **kwargs)  # refused before the (missing) file is read
    assert needle in str(e.value) and "fix:" in str(e.value)


@pytest.mark.parametrize(
    ("agent", "arg"), [("policy", "temperature=.nan"), ("random", "seed=.inf"), ("random", "x=[1, .nan]")]
)
def test_a_nan_agent_argument_names_its_key(roots: list[str], tmp_path: Path, capsys, agent: str, arg: str) -> None:
    extra = ["--checkpoint", str(tmp_path / "p.pt")] if agent == "policy" else []
    rc, _, errors = run(["evaluate", "--agent", agent, "--agent-arg", arg, *extra, *roots], capsys)
    one_line(rc, errors, f"--agent-arg {arg!r}", "not a finite number")
    assert not (tmp_path / "out").exists()


# -- 11, 12: a server that does not speak the protocol -------------------------------------------------------
@contextmanager
def fake_server(reply: Callable[[dict], list[bytes]]) -> Iterator[int]:
    """A ROUTER on a free loopback port answering every message with `reply(header)` (header: the request's
    msgpack map); yields the port."""
    ctx = zmq.Context()
    sock = ctx.socket(zmq.ROUTER)
    sock.setsockopt(zmq.LINGER, 0)
    port = sock.bind_to_random_port("tcp://127.0.0.1")
    stop = threading.Event()

    def loop() -> None:
        while not stop.is_set():
            if sock.poll(50):
                ident, *frames = sock.recv_multipart()
                try:
                    header = msgpack.unpackb(frames[0], raw=False)
                except Exception:  # noqa: BLE001
                    header = {}
                if isinstance(header, dict) and header.get("op") != "close":
                    sock.send_multipart([ident, *reply(header)])

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    try:
        yield port
    finally:
        stop.set()
        thread.join(5)
        sock.close(0)
        ctx.term()


def hello(header: dict, **fields: Any) -> list[bytes]:
    base = {"op": "hello", "id": header.get("id"), "protocol": 1, "agent": "fake", "privileged": False, "batch": False}
    return [msgpack.packb({**base, **fields}, use_bin_type=True)]


GARBAGE = {
    "not msgpack": lambda h: [b"\xff\x00junk"],
    "extension type": lambda h: [msgpack.packb({"op": "hello", "id": h.get("id"), "x": msgpack.ExtType(5, b"x")})],
    "not a map": lambda h: [msgpack.packb([1, 2, 3])],
}


@pytest.mark.parametrize("kind", sorted(GARBAGE))
def test_a_reply_that_is_not_the_protocol_is_a_remote_error_naming_the_address(kind: str) -> None:
    with fake_server(GARBAGE[kind]) as port:
        with pytest.raises(RemoteError) as e:
            Client("127.0.0.1", port, timeout_s=5)
        assert e.value.kind == "protocol"
        assert f"the agent at tcp://127.0.0.1:{port} answered the handshake with a message that does not follow" in str(
            e.value
        )
        with pytest.raises(RemoteError) as e:
            check_remote(f"remote:127.0.0.1:{port}", RemoteConfig(timeout_s=5))
        assert f"127.0.0.1:{port}" in str(e.value) and "fix: check that" in str(e.value)


def test_garbage_during_a_run_names_the_episode_and_the_step() -> None:
    def reply(header: dict) -> list[bytes]:
        return hello(header) if header.get("op") == "hello" else [b"\xc1garbage"]

    with fake_server(reply) as port:
        agent = RemoteAgent(f"remote:127.0.0.1:{port}", RemoteConfig(timeout_s=5))
        try:
            agent.reset({"split": "val_seen", "scene_id": "a/scene1.glb", "episode_id": "7"})
            with pytest.raises(RemoteError) as e:
                agent.act({"depth": np.zeros((2, 2), np.float32), "goal": "bed"})
        finally:
            agent.close()
    msg = str(e.value)
    assert f"tcp://127.0.0.1:{port} answered step 1 of episode val_seen/scene1.glb/7 with a message" in msg
    assert "fix:" in msg and e.value.kind == "protocol"


def test_a_garbage_reply_on_the_command_line_is_one_remote_line(roots: list[str], tmp_path: Path, capsys) -> None:
    with fake_server(GARBAGE["not msgpack"]) as port:
        rc, _, errors = run(
            ["evaluate", "--agent", f"remote:127.0.0.1:{port}", "--set", "remote.timeout_s=5", *roots], capsys
        )
    one_line(rc, errors, f"tcp://127.0.0.1:{port} answered the handshake")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("fields", "needle"),
    [
        ({"observations": 5}, "answered the handshake with observations 5; expected a list of observation names"),
        ({"observations": "depth"}, "observations 'depth'; expected a list"),
        ({"observations": [1]}, "observations [1]; expected a list"),
        ({"observations": ["sonar"]}, "wants observations ['sonar'], which ovon does not provide"),
        ({"privileged": "false"}, "privileged 'false'; expected true or false"),
    ],
)
def test_bad_handshake_fields_are_one_config_line(fields: dict, needle: str) -> None:
    with fake_server(lambda h: hello(h, **fields)) as port:
        with pytest.raises(ConfigError) as e:
            check_remote(f"remote:127.0.0.1:{port}", RemoteConfig(timeout_s=5))
    assert needle in str(e.value) and "fix:" in str(e.value)


def test_good_handshake_observations_are_kept_in_order() -> None:
    with fake_server(lambda h: hello(h, observations=["goal", "depth"])) as port:
        agent = RemoteAgent(f"remote:127.0.0.1:{port}", RemoteConfig(timeout_s=5))
        agent.close()
    assert agent.observations == ("goal", "depth") and agent.name == "fake" and agent.privileged is False


# -- 13: addresses -------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("agent", "needle"),
    [
        ("remote:local host:5555", "HOST 'local host' is not a host name or IP address"),
        ("remote:http://127.0.0.1:5555", "holds a scheme"),
        ("remote:*:5555", "HOST '*' is an address to listen on"),
        ("remote:127.0.0.1:5555:1", "HOST '127.0.0.1:5555' holds ':'"),
        ("remote:[127.0.0.1]:5555", "in brackets is not an IPv6 address"),
    ],
)
def test_bad_hosts_are_refused_before_connecting(
    agent: str, needle: str, roots: list[str], tmp_path: Path, capsys
) -> None:
    with pytest.raises(ConfigError, match="fix: --agent remote:HOST:PORT") as e:
        parse_address(agent)
    assert needle in str(e.value)
    rc, _, errors = run(["evaluate", "--agent", agent, *roots], capsys)
    one_line(rc, errors, needle)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "agent", ["remote:[::1]:5555", "remote:localhost:5555", "remote:my-host.lan:80", "remote:10.0.0.1:1"]
)
def test_good_hosts_parse(agent: str) -> None:
    host, port = parse_address(agent)
    assert host and 1 <= port <= 65535


def test_a_host_that_does_not_resolve_says_so(monkeypatch) -> None:
    def no_such_host(*args: Any, **kw: Any) -> Any:
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", no_such_host)
    with pytest.raises(ConfigError) as e:
        check_remote("remote:no-such-host.invalid:5555", RemoteConfig(timeout_s=0.5))
    msg = str(e.value)
    assert "the host 'no-such-host.invalid' does not resolve (Name or service not known)" in msg
    assert "connection refused" not in msg and "fix:" in msg


@pytest.mark.parametrize("host", ["local host", "http://127.0.0.1", "*"])
def test_the_client_names_an_address_zeromq_refuses(host: str) -> None:
    with pytest.raises(RemoteError) as e:
        Client(host, 5555, timeout_s=0.5)
    assert e.value.kind == "address" and "cannot connect to tcp://" in str(e.value)


# -- 14: row names -------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["a|b", "x\n", "x\n" * 5000, "y" * 101, " ", "tab\there"])
def test_a_row_name_that_would_break_the_table_is_refused(name: str, tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as e:
        validate(EvalConfig(data=str(tmp_path), scenes=str(tmp_path), name=name))
    msg = str(e.value)
    assert msg.startswith("--name = ") and "without '|', line breaks" in msg and "\n" not in msg and len(msg) < 500


def test_a_good_row_name_is_kept(tmp_path: Path) -> None:
    cfg = validate(EvalConfig(data=str(tmp_path), scenes=str(tmp_path), name="VLFM (oracle, 0.5 m)"))
    assert cfg.name == "VLFM (oracle, 0.5 m)"


def test_the_name_option_on_the_command_line(roots: list[str], tmp_path: Path, capsys) -> None:
    rc, _, errors = run(["evaluate", "--agent", "random", "--name", "a|b", *roots], capsys)
    one_line(rc, errors, "--name = 'a|b'")
    assert not (tmp_path / "out").exists()


class _Still:
    def reset(self, episode_info: dict) -> None:
        pass

    def act(self, observation: dict) -> int:
        return 0


@pytest.mark.parametrize("name", ["x\n" * 5000, "a | b"])
def test_a_served_name_that_would_break_the_table_is_refused(name: str) -> None:
    with serving(_Still, name=name) as server:
        with pytest.raises(ConfigError) as e:
            check_remote(f"remote:127.0.0.1:{server.port}", RemoteConfig(timeout_s=5))
    msg = str(e.value)
    assert "cannot name a row of the table" in msg and "fix: pass --name NAME" in msg
    assert "\n" not in msg and len(msg) < 600


def test_a_served_name_is_the_row_name_when_it_fits() -> None:
    with serving(_Still, name="my agent (v2)") as server:
        assert check_remote(f"remote:127.0.0.1:{server.port}", RemoteConfig(timeout_s=5)).name == "my agent (v2)"


def test_dataclass_replace_keeps_str_paths(tmp_path: Path) -> None:
    """Stored as str in place: a frozen config (TrainConfig) too, so its JSON identity holds text."""
    from ovon.train import check_config

    cfg = check_config(dataclasses.replace(_tiny(), text_cache=tmp_path / "t.pt"))
    assert cfg.text_cache == str(tmp_path / "t.pt") and isinstance(cfg.text_cache, str)
