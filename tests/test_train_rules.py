"""RL scored by the rules it is trained under: the curriculum counts updates, evaluation's STOP rule takes over
for the last part of training, training episodes are as long as evaluated ones, and a policy is evaluated at the
temperature it acted at in training."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

torch.set_num_threads(1)

from ovon.config.task import TaskConfig  # noqa: E402
from ovon.env.sampler import EpisodeSampler  # noqa: E402
from ovon.sim.agent import STOP  # noqa: E402
from ovon.train.config import CurriculumConfig, train_preset  # noqa: E402
from ovon.train.run import policy_extra, schedule  # noqa: E402
from tests.test_env import given, make  # noqa: E402
from tests.test_sampler_curriculum import _distance, _Recorder, _specs  # noqa: E402


def test_the_curriculum_counts_the_trainers_updates() -> None:
    """unit updates: the cap is the same for every env at a given update and reaches every episode when the
    schedule says, however many episodes the env has started."""
    sampler = EpisodeSampler(
        _Recorder(), _specs(), seed=0, scene_repeat=2, curriculum_start_m=2.0, curriculum_updates=10
    )
    for _ in range(200):  # many episodes at update 0: the cap does not move
        sampler.reset()
    assert max(_distance(e) for e in sampler.env.started) <= 2.0
    sampler.set_update(5)
    assert sampler.max_distance() == pytest.approx(2.0 + 0.5 * (10.5 - 2.0))
    sampler.set_update(10)
    assert sampler.max_distance() == float("inf")
    for _ in range(100):
        sampler.reset()
    assert max(_distance(e) for e in sampler.env.started[200:]) > 9.0


def test_evaluations_stop_rule_takes_over_at_the_scheduled_update() -> None:
    """Before `strict_stop_from` a STOP far from the goal goes on (task.failed_stop_ends false); from that
    update on, episodes start under evaluation's rule and such a STOP ends the episode as a failure. The rule
    of the episode in progress is part of the resume state."""
    spec = given()["episode"]

    def sampler() -> EpisodeSampler:
        env = make(task=TaskConfig(failed_stop_ends=False, max_steps=20))
        return EpisodeSampler(env, [spec], seed=0, strict_stop_from=3)

    s = sampler()
    s.set_update(2)
    s.reset()
    _, _, term, _, _ = s.step(STOP)
    assert not term and not s.strict_stop
    s.set_update(3)  # the episode in progress keeps its rule
    _, _, term, _, _ = s.step(STOP)
    assert not term
    s.reset()
    state = s.get_state()
    _, _, term, _, info = s.step(STOP)
    assert term and s.strict_stop and not info["metrics"]["success"]
    restored = sampler()
    restored.set_state(state)
    assert restored.strict_stop and restored.update == 3
    _, _, term, _, _ = restored.step(STOP)
    assert term


def test_the_schedule_is_a_fraction_of_the_runs_updates() -> None:
    cfg = train_preset("tiny", algo="ppo", max_updates=40, failed_stop_ends_from=0.75)
    cfg = dataclasses.replace(
        cfg,
        task=dataclasses.replace(cfg.task, failed_stop_ends=False),
        curriculum=CurriculumConfig(start_m=2.0, unit="updates", fraction=0.5),
    )
    assert schedule(cfg, cfg.task, 40) == {
        "curriculum_start_m": 2.0,
        "curriculum_episodes": 0,
        "curriculum_updates": 20,
        "strict_stop_from": 30,
    }
    # every STOP ends training episodes already: nothing to switch
    assert schedule(cfg, TaskConfig(), 40)["strict_stop_from"] is None
    # 1 = never: the whole run under the task's rule
    never = dataclasses.replace(cfg, failed_stop_ends_from=1.0)
    assert schedule(never, never.task, 40)["strict_stop_from"] is None
    by_episodes = dataclasses.replace(cfg, curriculum=CurriculumConfig(start_m=2.0, unit="episodes", episodes=300))
    got = schedule(by_episodes, by_episodes.task, 40)
    assert (got["curriculum_episodes"], got["curriculum_updates"]) == (300, 0)


def test_a_ppo_run_tells_its_envs_which_update_runs(tmp_path: Path) -> None:
    """The loop's clock reaches the samplers: the saved env states carry the update that last started, and
    the episodes started from the scheduled update on are under evaluation's rule."""
    from ovon.train import train
    from ovon.train.checkpoint import load_checkpoint
    from ovon.train.episodes import adhoc_specs

    cfg = train_preset("tiny", algo="ppo", max_updates=4, checkpoint_every=4, failed_stop_ends_from=0.25)
    cfg = dataclasses.replace(cfg, task=dataclasses.replace(cfg.task, failed_stop_ends=False, max_steps=5))
    train(cfg, adhoc_specs([0], categories=["couch", "bed"]), tmp_path)
    envs = load_checkpoint(tmp_path)["ranks"][0]["env"]
    assert [e["update"] for e in envs] == [3, 3]
    assert all(e["strict_stop"] for e in envs)  # 5-step episodes: each env has started one since update 1


def test_cpu_training_episodes_are_as_long_as_evaluated_ones() -> None:
    from ovon.evaluate.config import EvalConfig

    assert train_preset("cpu-small").task.max_steps == EvalConfig().task.max_steps == 500


def test_the_cpu_rl_recipe_ends_under_evaluations_rules(tmp_path: Path) -> None:
    """The experiment's RL cells: the curriculum counts updates and is done by half of the run; the first phase
    ends under evaluation's STOP rule, the second phase trains under it throughout."""
    from ovon.experiments.definitions import load_experiment
    from ovon.experiments.plan import resolve

    plan = resolve([load_experiment("main")], "cpu", tmp_path)
    warm = plan.cells["train:rl-warmup"].train_cfg
    assert warm.curriculum.unit == "updates" and warm.curriculum.fraction <= 0.5
    assert not warm.task.failed_stop_ends and warm.failed_stop_ends_from < 1.0
    assert plan.cells["train:rl"].train_cfg.task.failed_stop_ends
    assert warm.task.max_steps == 500


def test_a_policy_is_evaluated_at_the_temperature_it_trained_at(tmp_path: Path) -> None:
    from ovon.agents.policy_agent import PolicyAgent
    from ovon.models.config import EncoderConfig, policy_preset
    from ovon.models.policy import build_policy

    ppo = train_preset("tiny", algo="ppo")
    ppo = dataclasses.replace(ppo, ppo=dataclasses.replace(ppo.ppo, temperature=0.5))
    policy = build_policy(policy_preset("tiny"), 16, 8, EncoderConfig(oracle_grid=1, oracle_global=False))
    extra = policy_extra(ppo, "ppo-finetune", 1, 1, policy)
    assert extra["acting_temperature"] == 0.5
    assert policy_extra(ppo, "dagger", 1, 1, policy)["acting_temperature"] == 1.0  # the cross-entropy's
    policy.save(tmp_path / "p.pt", extra={"acting_temperature": 0.5})
    assert PolicyAgent(str(tmp_path / "p.pt"), deterministic=False).temperature == 0.5
    assert PolicyAgent(str(tmp_path / "p.pt"), deterministic=False, temperature=0.8).temperature == 0.8
    policy.save(tmp_path / "old.pt")  # written before checkpoints recorded it
    assert PolicyAgent(str(tmp_path / "old.pt"), deterministic=False).temperature == 1.0
