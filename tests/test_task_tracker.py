"""Metrics and failure labels against hand-computed trajectories (docs/spec.md#metrics, #failure-labels)."""

import math

import numpy as np
import pytest

from ovon.config.task import RewardConfig, TaskConfig
from ovon.task.tracker import FAILURE_LABELS, Distractor, EpisodeTracker

GOAL = 7  # goal instance id
OTHER = 9  # a distractor instance id


def straight_line_field(goal_x: float):
    """Geodesic = |x - goal_x| along a corridor; viewpoint at x = goal_x."""
    return lambda p: abs(float(p[0]) - goal_x)


def frame(ids: dict[int, float] | None = None, size: int = 100) -> np.ndarray:
    """A semantic frame where each id covers the given fraction of pixels."""
    sem = np.zeros(size * size, dtype=np.int32)
    start = 0
    for i, frac in (ids or {}).items():
        n = int(round(frac * sem.size))
        sem[start : start + n] = i
        start += n
    return sem.reshape(size, size)


def make(goal_x=3.0, max_steps=500, distractors=()):
    return EpisodeTracker(
        straight_line_field(goal_x), frozenset({GOAL}), TaskConfig(max_steps=max_steps), list(distractors)
    )


def walk(t, xs, stop_at_end, frames=None, collided=False):
    for i, x in enumerate(xs):
        last = i == len(xs) - 1
        sem = frames[i] if frames is not None else None
        t.update(np.array([x, 0.0, 0.0]), stop=stop_at_end and last, collided=collided, semantic=sem)


def test_success_spl_is_shortest_over_actual_path():
    t = make(goal_x=3.0)
    t.reset(np.zeros(3))
    # detour: 1 m backwards, then 4 m forward -> L = 1 + 4 = 5, d0 = 3, d_T = 0
    walk(t, [-0.5, -1.0, 0.0, 1.0, 2.0, 3.0], stop_at_end=True)
    m = t.metrics()
    assert m.success and m.failure is None
    assert m.path_length == pytest.approx(5.0)
    assert m.spl == pytest.approx(3.0 / 5.0)
    assert m.soft_spl == pytest.approx(3.0 / 5.0)
    assert m.steps == 6


def test_soft_spl_without_stop_and_failure():
    t = make(goal_x=4.0, max_steps=2)
    t.reset(np.zeros(3))
    walk(t, [1.0, 2.0], stop_at_end=False)
    assert t.done
    m = t.metrics()
    assert not m.success and m.spl == 0.0
    # progress 1 - 2/4 = 0.5, efficiency d0/max(d0, L) = 4/4 = 1
    assert m.soft_spl == pytest.approx(0.5)
    assert m.failure == "timeout_missed_goal"


def test_spl_uses_3d_displacement():
    t = make(goal_x=1.0)
    t.reset(np.zeros(3))
    t.update(np.array([1.0, 1.0, 0.0]), stop=True, collided=False)  # climbs 1 m while moving 1 m
    m = t.metrics()
    assert m.path_length == pytest.approx(math.sqrt(2.0))
    assert m.spl == pytest.approx(1.0 / math.sqrt(2.0))


def test_stop_just_outside_region_fails():
    t = make(goal_x=1.0)
    t.reset(np.zeros(3))
    t.update(np.array([0.74, 0.0, 0.0]), stop=True, collided=False)  # d = 0.26
    assert not t.metrics().success
    t2 = make(goal_x=1.0)
    t2.reset(np.zeros(3))
    t2.update(np.array([0.76, 0.0, 0.0]), stop=True, collided=False)  # d = 0.24
    assert t2.metrics().success


def test_collisions_counted():
    t = make()
    t.reset(np.zeros(3))
    walk(t, [0.0, 0.0, 0.25], stop_at_end=False, collided=True)
    assert t.metrics().collisions == 3


# -- the seven failure labels, one scripted trajectory each ------------------------------------------
def labelled(xs, stop, frames=None, max_steps=500, distractors=()):
    t = make(goal_x=3.0, max_steps=max_steps if stop else len(xs), distractors=distractors)
    t.reset(np.zeros(3), frame())
    walk(t, xs, stop, frames)
    return t.metrics().failure


def test_timeout_missed_goal():
    assert labelled([0.5, 1.0], stop=False, frames=[frame(), frame()]) == "timeout_missed_goal"


def test_timeout_ignored_goal():
    seen = frame({GOAL: 0.05})
    assert labelled([0.5, 1.0], stop=False, frames=[seen, frame()]) == "timeout_ignored_goal"


def test_timeout_inside_the_success_region_is_ignored_goal_seen_or_not():
    """The paper's table has no row for a timeout that ends inside the region (entered, never left); it
    is `timeout_ignored_goal` (docs/spec.md), whether or not the goal was in view there."""
    assert labelled([2.0, 3.0], stop=False, frames=[frame(), frame()]) == "timeout_ignored_goal"
    assert labelled([2.0, 3.0], stop=False, frames=[frame(), frame({GOAL: 0.2})]) == "timeout_ignored_goal"
    assert labelled([2.0, 2.5], stop=False, frames=[frame(), frame()]) == "timeout_missed_goal"  # never inside
    barely = frame({GOAL: 0.005})
    assert labelled([0.5, 1.0], stop=False, frames=[barely, barely]) == "timeout_missed_goal"


def test_seen_means_one_goal_instance_covers_one_percent():
    """Two goal instances at 0.6% of the frame each are not "seen" (the spec: *a* goal instance covering
    1%), as `goal_in_view` and the distractors already count per instance; one at 1.2% is."""
    t = EpisodeTracker(straight_line_field(3.0), frozenset({GOAL, GOAL + 1}), TaskConfig(max_steps=2), [])
    t.reset(np.zeros(3), frame())
    walk(t, [0.5, 1.0], False, [frame({GOAL: 0.006, GOAL + 1: 0.006})] * 2)
    assert t.metrics().failure == "timeout_missed_goal" and not t.goal_seen
    t.reset(np.zeros(3), frame())
    walk(t, [0.5, 1.0], False, [frame({GOAL: 0.012}), frame()])
    assert t.metrics().failure == "timeout_ignored_goal"


def test_timeout_left_goal():
    f = frame({GOAL: 0.1})
    assert labelled([2.0, 3.0, 2.0], stop=False, frames=[f, f, f]) == "timeout_left_goal"


def test_stop_wrong_object():
    box = Distractor(OTHER, "toaster", np.array([0.8, 0.0, -0.2]), np.array([1.2, 0.5, 0.2]))
    f = frame({OTHER: 0.2})
    assert labelled([0.5, 1.0], stop=True, frames=[f, f], distractors=[box]) == "stop_wrong_object"


def test_stop_near_unseen_distractor_is_not_wrong_object():
    box = Distractor(OTHER, "toaster", np.array([0.8, 0.0, -0.2]), np.array([1.2, 0.5, 0.2]))
    assert labelled([0.5, 1.0], stop=True, frames=[frame(), frame()], distractors=[box]) == "stop_never_saw_goal"


def test_distractor_seen_earlier_but_not_in_view_at_stop_is_not_wrong_object():
    """The label needs the other object in the STOP frame: a glimpse earlier on does not count."""
    box = Distractor(OTHER, "toaster", np.array([0.8, 0.0, -0.2]), np.array([1.2, 0.5, 0.2]))
    seen_then = [frame({OTHER: 0.2, GOAL: 0.05}), frame({GOAL: 0.05})]
    assert labelled([0.5, 1.0], stop=True, frames=seen_then, distractors=[box]) == "stop_too_far"
    never_goal = [frame({OTHER: 0.2}), frame()]
    assert labelled([0.5, 1.0], stop=True, frames=never_goal, distractors=[box]) == "stop_never_saw_goal"


def test_distractor_in_view_below_seen_threshold_is_not_wrong_object():
    box = Distractor(OTHER, "toaster", np.array([0.8, 0.0, -0.2]), np.array([1.2, 0.5, 0.2]))
    f = [frame({GOAL: 0.05}), frame({OTHER: 0.005})]
    assert labelled([0.5, 1.0], stop=True, frames=f, distractors=[box]) == "stop_too_far"


def test_distractor_in_view_but_farther_than_one_metre_is_not_wrong_object():
    box = Distractor(OTHER, "toaster", np.array([2.2, 0.0, -0.2]), np.array([2.6, 0.5, 0.2]))  # 1.2 m away
    f = frame({OTHER: 0.2, GOAL: 0.05})
    assert labelled([0.5, 1.0], stop=True, frames=[f, f], distractors=[box]) == "stop_too_far"


def test_near_miss_after_seeing_the_goal_is_stop_too_far():
    """STOP 0.3 m outside the success region with the goal in view (VLFM's typical miss)."""
    f = frame({GOAL: 0.3})
    assert labelled([1.0, 2.0, 2.7], stop=True, frames=[f] * 3) == "stop_too_far"


def test_stop_too_far():
    f = frame({GOAL: 0.1})
    assert labelled([1.0, 2.0], stop=True, frames=[f, f]) == "stop_too_far"


def test_stop_left_goal():
    f = frame({GOAL: 0.1})
    assert labelled([2.0, 3.0, 2.0, 1.5], stop=True, frames=[f] * 4) == "stop_left_goal"


def test_stop_never_saw_goal():
    assert labelled([0.5], stop=True, frames=[frame()]) == "stop_never_saw_goal"


def test_labels_are_the_seven_of_task_md():
    assert len(FAILURE_LABELS) == 7 and len(set(FAILURE_LABELS)) == 7


def test_dense_and_sparse_rewards():
    t = EpisodeTracker(straight_line_field(3.0), frozenset({GOAL}), TaskConfig())
    t.reset(np.zeros(3))
    t.update(np.array([1.0, 0, 0]), stop=False, collided=False)
    assert t.reward() == pytest.approx(1.0 - 0.01)
    t.update(np.array([3.0, 0, 0]), stop=True, collided=False)
    assert t.reward() == pytest.approx(2.5)
    s = EpisodeTracker(straight_line_field(3.0), frozenset({GOAL}), TaskConfig(reward=RewardConfig(kind="sparse")))
    s.reset(np.zeros(3))
    s.update(np.array([1.0, 0, 0]), stop=False, collided=False)
    assert s.reward() == pytest.approx(-0.001)
    s.update(np.array([1.0, 0, 0]), stop=False, collided=True)
    assert s.reward() == pytest.approx(-0.001 - 0.003)


def test_where_the_episode_ended():
    """`goal_in_view` is the last frame only; `distance_to_object` comes from the tracker's box distance."""
    t = make(goal_x=3.0)
    t.reset(np.zeros(3))
    walk(t, [1.0, 2.0], stop_at_end=True, frames=[frame({GOAL: 0.05}), frame()])
    m = t.metrics()
    assert m.goal_seen and not m.goal_in_view and m.distance_to_object is None
    t = EpisodeTracker(
        straight_line_field(3.0), frozenset({GOAL}), TaskConfig(), object_distance_fn=lambda p: abs(4.0 - float(p[0]))
    )
    t.reset(np.zeros(3))
    walk(t, [1.0, 2.0], stop_at_end=True, frames=[frame(), frame({GOAL: 0.05})])
    m = t.metrics()
    assert m.goal_in_view and m.distance_to_object == pytest.approx(2.0)
    assert m.failure == "stop_too_far"


def test_goal_view_reward_pays_only_new_view_of_the_goal():
    """dense_goal_view: the increase of the largest goal fraction seen so far (the first frame is free)."""
    cfg = TaskConfig(reward=RewardConfig(dense_slack=0.0, dense_goal_view=2.0))
    t = EpisodeTracker(lambda p: 5.0, frozenset({GOAL}), cfg)
    t.reset(np.zeros(3), semantic=frame({GOAL: 0.02}))
    expected = []
    for frac in (0.0, 0.05, 0.03, 0.10, 0.10):
        t.update(np.zeros(3), stop=False, collided=False, semantic=frame({GOAL: frac} if frac else None))
        expected.append(t.reward())
    assert expected == pytest.approx([0.0, 2.0 * 0.03, 0.0, 2.0 * 0.05, 0.0])
    t.update(np.zeros(3), stop=False, collided=False)  # no frame: nothing paid
    assert t.reward() == pytest.approx(0.0)
    off = EpisodeTracker(lambda p: 5.0, frozenset({GOAL}), TaskConfig(reward=RewardConfig(dense_slack=0.0)))
    off.reset(np.zeros(3), semantic=frame())
    off.update(np.zeros(3), stop=False, collided=False, semantic=frame({GOAL: 0.5}))
    assert off.reward() == 0.0 and off.goal_seen


def test_a_failed_stop_that_does_not_end_the_episode_costs_and_goes_on():
    """task.failed_stop_ends=false (training only): a STOP outside the region costs dense_failed_stop and the
    episode continues; a STOP inside still ends it as a success. The default ends it as a failure."""
    reward = RewardConfig(dense_failed_stop=-0.25, dense_slack=0.0)
    cfg = TaskConfig(failed_stop_ends=False, reward=reward)
    t = EpisodeTracker(straight_line_field(1.0), frozenset({GOAL}), cfg)
    t.reset(np.zeros(3))
    t.update(np.array([0.25, 0.0, 0.0]), stop=True, collided=False)  # 0.75 m from the viewpoint
    assert not t.done and not t.called_stop and t.failed_stops == 1
    assert t.reward() == pytest.approx(0.25 - 0.25)  # progress minus the failed STOP
    t.update(np.array([0.5, 0.0, 0.0]), stop=False, collided=False)
    assert t.reward() == pytest.approx(0.25) and not t.stopped_outside
    t.update(np.array([0.9, 0.0, 0.0]), stop=True, collided=False)  # inside the 0.25 m region
    assert t.done and t.success and t.reward() == reward.dense_success
    ends = EpisodeTracker(straight_line_field(1.0), frozenset({GOAL}), TaskConfig(reward=reward))
    ends.reset(np.zeros(3))
    ends.update(np.array([0.25, 0.0, 0.0]), stop=True, collided=False)
    assert ends.done and not ends.success and ends.failed_stops == 0


def test_best_progress_pays_only_for_a_new_closest_distance():
    """task.reward.dense_progress=best: walking away costs nothing, coming back pays nothing, a new minimum
    pays its decrease; "delta" (the paper's) pays every change."""
    reward = RewardConfig(dense_slack=0.0, dense_progress="best")
    t = EpisodeTracker(straight_line_field(3.0), frozenset({GOAL}), TaskConfig(reward=reward))
    t.reset(np.zeros(3))
    got = []
    for x in (0.5, 0.25, 0.0, 0.5, 1.0, 1.5):
        t.update(np.array([x, 0.0, 0.0]), stop=False, collided=False)
        got.append(t.reward())
    assert got == pytest.approx([0.5, 0.0, 0.0, 0.0, 0.5, 0.5])
    delta = EpisodeTracker(
        straight_line_field(3.0), frozenset({GOAL}), TaskConfig(reward=RewardConfig(dense_slack=0.0))
    )
    delta.reset(np.zeros(3))
    delta.update(np.array([0.5, 0.0, 0.0]), stop=False, collided=False)
    delta.update(np.array([0.25, 0.0, 0.0]), stop=False, collided=False)
    assert delta.reward() == pytest.approx(-0.25)


def test_goal_viewpoints_on_another_floor_are_not_goals_on_the_start_floor():
    """A viewpoint upstairs stands over a navigable cell downstairs; it must not become a goal there (the
    episode's distance and success region are the start floor's, as the dataset validator measures d0)."""
    import numpy as np

    from ovon.config.sim import SimConfig
    from ovon.config.task import TaskConfig
    from ovon.sim.geodesic import distance_field
    from ovon.sim.world import build_world
    from ovon.task.episode import EpisodeSpec, GoalViewpoint
    from ovon.task.setup import prepare_episode

    world = build_world("procedural:1", SimConfig())
    down, up = world.nav.floors
    rng = np.random.default_rng(0)
    start = down.random_point(rng)
    far = next(
        p
        for p in (down.random_point(rng) for _ in range(500))
        if 4.0 < distance_field(down, p[None]).distance(start) < 1e9
    )
    above = start + np.array([0.3, up.height - down.height, 0.0])  # upstairs, over the start's neighbourhood
    assert world.nav.floor_index(above) == up.floor and down.is_navigable(above)
    cat = world.scene.objects[0].category
    spec = EpisodeSpec(
        "two-floors",
        world.scene.scene_id,
        cat,
        start_position=start,
        start_yaw=0.0,
        viewpoints=[GoalViewpoint(far, 0.0), GoalViewpoint(above, 0.0)],
    )
    setup = prepare_episode(world, spec, np.random.default_rng(0), TaskConfig())
    expect = distance_field(down, far[None]).distance(start)
    assert abs(setup.goal_field.distance(start) - expect) < 1e-6 and expect > 4.0
    assert [tuple(v.position) for v in setup.viewpoints] == [tuple(far)]
    only_up = EpisodeSpec(
        "upstairs",
        world.scene.scene_id,
        cat,
        start_position=start,
        start_yaw=0.0,
        viewpoints=[GoalViewpoint(above, 0.0)],
    )
    with pytest.raises(ValueError, match="no goal viewpoint on the start's floor 0"):
        prepare_episode(world, only_up, np.random.default_rng(0), TaskConfig())
    # a goal on the start's floor that no path reaches is refused at reset, not after a whole episode
    rows, cols = np.nonzero(down.navigable & (down.islands != down.island_of(start)))  # another island
    island = np.asarray(down.cell_to_world(int(rows[0]), int(cols[0])))
    cut_off = EpisodeSpec(
        "island",
        world.scene.scene_id,
        cat,
        start_position=start,
        start_yaw=0.0,
        viewpoints=[GoalViewpoint(island, 0.0)],
    )
    with pytest.raises(ValueError, match="no goal viewpoint is reachable from the start"):
        prepare_episode(world, cut_off, np.random.default_rng(0), TaskConfig())
