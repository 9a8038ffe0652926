"""The online search's two-step look-ahead (agent.search.online.OnlineSearch.choose): a look on
the way to a larger one goes first; greedy choice, without it, takes the larger one."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from ctxsearch.agent.search import online as on
from ctxsearch.agent.search.config import OnlineConfig
from ctxsearch.envs.robot_spec import RobotPose, TimeModel


def _search(x: float = 0.0, y: float = 0.0, lookahead: bool = True) -> on.OnlineSearch:
    """An OnlineSearch with only what ``choose`` reads: the robot's pose, the time model, the
    online settings (``online.lookahead``) and the calibration (none yet: every kind's seconds
    taken as estimated)."""
    s = on.OnlineSearch.__new__(on.OnlineSearch)
    body = SimpleNamespace(pose=lambda: RobotPose(x, y, 0.0, 0.0, 0.0))
    s.ctx = SimpleNamespace(body=body, time_model=TimeModel())
    s.settings = OnlineConfig(lookahead=lookahead)
    s.took = {}
    return s


def _option(name, found, seconds, at, kind="region"):
    return on.Option(found / seconds, name, lambda: None, kind, seconds, at, at)


@pytest.fixture
def far_and_on_the_way():
    # 0.5 m/s: the region 10 m away costs 20 s of drive and 10 s of looking; the sweep at 9 m
    # costs 18 s of drive and 6 s of images. Alone the region is the better rate (1/60 > 1/80).
    far = _option("region", 0.5, 30.0, (10.0, 0.0))
    near = _option("sweep", 0.3, 24.0, (9.0, 0.0), "explore")
    return far, near


def test_greedy_takes_the_best_rate(far_and_on_the_way):
    far, near = far_and_on_the_way
    assert _search(lookahead=False).choose([near, far]) == (far, None)
    assert OnlineConfig().lookahead is False  # greedy is the default


def test_the_look_ahead_takes_the_look_on_the_way_first(far_and_on_the_way):
    """Sweep then region: (0.5 + 0.3) / (24 + 0.7 * (30 - 20 + 2)) = 0.0247 per second; region
    then sweep: 0.8 / (30 + 0.5 * (24 - 18 + 2)) = 0.0235; either beats the region alone."""
    far, near = far_and_on_the_way
    best, then = _search().choose([far, near])
    assert (best, then) == (near, far)
    assert best is _search().choose([near, far])[0]  # the order the options come in is moot


def test_the_look_ahead_leaves_a_lone_or_far_better_option_first(far_and_on_the_way):
    far, near = far_and_on_the_way
    assert _search().choose([far]) == (far, None)
    # behind the robot, 9 m the other way: no detour pays
    behind = _option("sweep", 0.3, 24.0, (-9.0, 0.0), "explore")
    best, _ = _search().choose([far, behind])
    assert best is far
    # the calibration scales a kind's seconds as it scales the greedy rate
    s = _search()
    s.took = {"explore": [10.0, 400.0]}  # sweeps took 40x their estimate so far
    assert s.choose([far, near])[0] is far


def test_found_is_the_rate_times_the_seconds():
    o = _option("x", 0.25, 8.0, (0.0, 0.0))
    assert o.found == pytest.approx(0.25)
    assert np.isclose(o.rate, 0.25 / 8.0)


def test_what_the_second_look_finds_is_what_the_first_leaves(far_and_on_the_way):
    """m_b is b's own find times the share of it that a leaves: a sweep that finds most of a
    region's points first leaves the region little, so the plan of both is not counted twice."""
    weights = np.array([0.4, 0.4, 0.2])
    region = (np.array([0, 1]), np.array([0.9, 0.9]))
    assert on._left_after(None, region, weights) == 1.0  # a detour overlaps nothing
    assert on._left_after(region, region, weights) == pytest.approx(0.1)
    elsewhere = (np.array([2]), np.array([0.5]))
    assert on._left_after(region, elsewhere, weights) == 1.0
    far, near = far_and_on_the_way
    s = _search()
    # the sweep on the way shows the region's points as well as the look would: no plan pays
    # for it, and the region alone is the better rate
    far_f = replace(far, finds=region)
    near_f = replace(near, finds=region)
    assert s.choose([far_f, near_f], weights) == (far_f, None)
