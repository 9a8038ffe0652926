"""The Gymnasium search task (agent.gym_env): registration, Gymnasium's own checker, the
benchmark's episodes, the time model's seconds as reward, termination and truncation, the
learned context, one-line errors, and the example script."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import ctxsearch.agent.gym_env as G
from ctxsearch.agent.search import episode as S
from ctxsearch.agent.search import oracle as O
from ctxsearch.agent.search.draw import DrawSpec, make_episodes, remembered_draws
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.robot_spec import TimeModel
from ctxsearch.knowledge.base import KnowledgeBase
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.scripts.examples import gym_random_agent

pytestmark = pytest.mark.render
SIZE = {"width": 64, "height": 48}


def make(**kw) -> gymnasium.Env:
    return gymnasium.make(G.ENV_ID, style="office", detector="perfect", **SIZE, **kw)


def test_registered_on_import_and_passes_gymnasiums_checker():
    assert G.ENV_ID in gymnasium.registry
    env = make(render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    assert [str(w.message) for w in caught] == []
    frame = env.unwrapped.render()
    assert frame.shape == (240, 320, 3) and frame.dtype == np.uint8
    env.close()
    env.close()  # twice is fine


def _benchmarks(style, n, seed, catalog, **kw):
    """The benchmark's draw of ``n`` episodes, asking only whether the target can be found (the
    same worlds, starts and drops as the full draw: test_search_protocol)."""
    return make_episodes(replace(DrawSpec.make(style, n, seed, catalog, **kw), first_view=False),
                         catalog)  # fmt: skip


def test_reset_draws_the_benchmarks_episodes(catalog):
    """Inside ``remembered_draws`` the task's draw is the benchmark's reference draw made again
    exactly when the task's spec is the benchmark's (else it draws its own and differs)."""
    style = resolve_style("office", catalog)
    env = make()
    G._DRAWS.clear()  # the task's own memo: every draw below goes through draw_episodes
    with remembered_draws():
        for seed, index in ((0, 0), (7, 0), (3, 1)):
            want = _benchmarks(style, index + 1, seed, catalog)[index]
            _, info = env.reset(seed=seed, options={"index": index})
            ep = env.unwrapped.episode
            assert (ep.room_seed, ep.target, ep.start) == (want.room_seed, want.target, want.start)
            assert info["room_seed"] == want.room_seed and info["target"] == want.target
            pose = env.unwrapped.world.pose()
            assert (pose.x, pose.y) == pytest.approx((want.start.x, want.start.y), abs=1e-3)
        env.close()
        learned = {S.held_out_seed(0, 0), S.held_out_seed(0, 2)}  # rooms a store learned in
        want = _benchmarks(style, 2, 0, catalog, exclude_seeds=learned)
        got = [G.draw_episode(style, 0, catalog, index=i, exclude_seeds=learned)[0]
               for i in range(2)]  # fmt: skip
    assert got == want and not learned & {e.room_seed for e in got}


def _run(env: gymnasium.Env, seed: int, actions) -> list:
    out = [env.reset(seed=seed)[0]]
    for a in actions:
        out.append(env.step(a)[0])
    return out


def test_same_seed_same_world_start_target_and_observations():
    actions = [7, 3, 7, 1, 0, 7, 6, 7]
    a, b = make(), make()
    ra, rb = _run(a, 5, actions), _run(b, 5, actions)
    for oa, ob in zip(ra, rb, strict=True):
        assert oa.keys() == ob.keys()
        for k in oa:
            np.testing.assert_array_equal(oa[k], ob[k])
    assert ra[-1]["rgb"].any()  # a look really shows the room
    other = _run(a, 6, actions)
    assert a.unwrapped.episode.room_seed != b.unwrapped.episode.room_seed
    assert not np.array_equal(other[-1]["pose"], ra[-1]["pose"])
    a.close()
    b.close()


def test_reward_is_minus_the_time_models_seconds():
    env = make()
    obs, _ = env.reset(seed=1)
    tm = TimeModel()
    yaw = float(obs["pose"][2])
    _, r, *_ = env.step(G.ACTIONS.index("turn_left"))
    assert r == pytest.approx(-tm.turn_time(yaw, yaw + G.TURN_RAD), rel=1e-6)
    _, r, *_ = env.step(G.ACTIONS.index("tilt_down"))
    assert r == pytest.approx(-tm.head_time(0.0, 0.0, 0.0, -G.TILT_RAD), abs=2e-3)
    charged = -r
    obs, r, *_, info = env.step(G.ACTIONS.index("look"))
    assert r == pytest.approx(-tm.image_cost)
    charged += -r + tm.turn_time(yaw, yaw + G.TURN_RAD)
    assert info["action"] == "look" and info["seconds"] == pytest.approx(-r)
    assert obs["elapsed"][0] == pytest.approx(charged, rel=1e-5) == info["elapsed"]
    before = obs["pose"].copy()
    obs, r, *_ = env.step(G.ACTIONS.index("forward"))
    moved = float(np.hypot(*(obs["pose"][:2] - before[:2])))
    assert moved <= G.FORWARD_M + 0.02
    assert r == pytest.approx(-tm.travel_time(moved), abs=0.02) if moved > 0 else r == 0.0
    env.close()


def test_terminates_on_a_true_target_and_truncates_at_the_budget():
    env = make()
    env.reset(seed=0)  # the benchmark's office episode 0: the target is not in view at the start
    base = env.unwrapped
    _, _, terminated, _, _ = env.step(G.ACTIONS.index("look"))
    assert not terminated
    # Put the robot where the oracle would look from (head included), then look.
    eye = O.OracleEye(base.world, base.layout, base.catalog, None, base.episode.target)
    view = O.oracle_view(
        eye, base.grid, base.world.pose(), base.world.sim_time, base.world.time_model
    )
    base.world.reset_pose(view.gaze.pose)
    t0 = base.elapsed
    _, reward, terminated, truncated, info = env.step(G.ACTIONS.index("look"))
    assert terminated and not truncated and info["success"]
    assert info["found_id"] in {o.id for o in base.layout.objects if o.type == base.episode.target}
    # the benchmark's success: the image that showed the target and the one that confirmed it
    assert -reward == pytest.approx(2 * base.time_model.image_cost)
    assert base.elapsed - t0 == pytest.approx(2 * base.time_model.image_cost)
    env.close()

    env = make(budget_s=2.0)
    env.reset(seed=0)
    steps, truncated = 0, False
    while not truncated:
        _, _, terminated, truncated, info = env.step(G.ACTIONS.index("turn_left"))
        steps += 1
        assert not terminated and steps < 20
    assert info["elapsed"] >= 2.0 > info["elapsed"] - TimeModel().turn_time(0.0, G.TURN_RAD) - 1e-9
    env.close()


def test_context_feature_ranks_the_learned_relation_volumes(catalog):
    kb = KnowledgeBase(catalog)
    for _ in range(20):  # desks always had a cup on top, never one under them
        kb.record_examination("Desk", [("ON-TOP-OF-DESK", "Cup")])
    env = make(kb=kb, top_k=4)
    assert env.observation_space["context"].shape == (4, len(G.CONTEXT_FEATURES))
    seed = next(s for s in range(40) if env.reset(seed=s)[1]["target"] == "Cup")
    obs, _ = env.reset(seed=seed)
    base = env.unwrapped
    np.testing.assert_array_equal(obs["context"], 0.0)  # nothing detected yet
    for a in [7, 3, 7, 3, 7, 3, 7, 4, 4, 4, 4, 7, 4, 7, 4, 7]:
        obs, _, terminated, *_ = env.step(a)
        if any(o.type == "Desk" for o in base._known.values()) or terminated:
            break
    ctx = obs["context"]
    desks = [o for o in base._known.values() if o.type == "Desk"]
    assert desks, "the office episode shows a desk"
    valid = ctx[ctx[:, -1] == 1.0]
    assert len(valid) >= 1
    lo, hi = kb.interval("ON-TOP-OF-DESK", "Cup")
    assert valid[0, 7:9] == pytest.approx((lo, hi))  # the best row: on top of a desk
    assert any(
        np.allclose(valid[0, :2], d.position[:2], atol=max(d.size) / 2 + 1e-3) for d in desks
    )
    assert (valid[:, 7] <= valid[:, 8]).all() and list(valid[:, 7]) == sorted(valid[:, 7])[::-1]
    assert env.observation_space["context"].contains(ctx)
    env.close()


def test_on_the_remembered_map_the_toured_furniture_is_context_from_the_start(catalog):
    kb = KnowledgeBase(catalog)
    for _ in range(20):
        kb.record_examination("Desk", [("ON-TOP-OF-DESK", "Cup")])
    env = make(kb=kb, top_k=4, map="remembered")
    seed = next(s for s in range(40) if env.reset(seed=s)[1]["target"] == "Cup")
    obs, info = env.reset(seed=seed)
    base = env.unwrapped
    assert info["day"] == 1 and info["remembered_furniture"] > 0
    assert base.episode.day == 1 and base.home.day == 0
    assert {o.id for o in base.home.furniture} <= {
        o.id for o in base.layout.objects if catalog.type(o.type).is_furniture
    }
    assert any(o.type == "Desk" for o in base.home.furniture)
    assert obs["context"][0, -1] == 1.0  # a desk's volume ranked before any image
    given = make(kb=kb, top_k=4)
    obs_g, info_g = given.reset(seed=seed)
    assert info_g["remembered_furniture"] == 0 and info_g["day"] == 0
    np.testing.assert_array_equal(obs_g["context"], 0.0)
    env.close()
    given.close()


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"map": "built"}, "map must be one of"),
        ({"style": "no_such_style"}, "no_such_style"),
        ({"detector": "no_such_detector"}, "no_such_detector"),
        ({"width": 0}, "image size"),
        ({"width": 5000}, "image size"),
        ({"budget_s": -1.0}, "budget_s"),
        ({"top_k": 0}, "top_k"),
        ({"kb": "/nonexistent/kb.sqlite"}, "no such knowledge store"),
        ({"kb": str(Path(__file__).parent)}, "is a directory, not a regular file"),
    ],
)
def test_bad_input_is_one_line_error(kwargs, needle):
    args = {"style": "office", "detector": "perfect", **SIZE, **kwargs}
    with pytest.raises(CtxsearchError) as err:
        gymnasium.make(G.ENV_ID, **args)
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_step_needs_a_reset_and_a_valid_action():
    env = G.ObjectSearchEnv("office", "perfect", **SIZE)
    with pytest.raises(CtxsearchError, match="reset"):
        env.step(0)
    env.reset(seed=0)
    with pytest.raises(CtxsearchError, match="invalid action"):
        env.step(len(G.ACTIONS))
    with pytest.raises(CtxsearchError, match="index"):
        env.reset(seed=0, options={"index": -1})
    env.close()


def test_example_runs_a_random_agent_and_exhaustive(capsys):
    assert gym_random_agent.main(["--steps", "30", "--seed", "2"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("random agent: ") and "simulated s" in out[0]
    assert out[1].startswith("exhaustive: ") and "simulated s" in out[1]
    assert math.isfinite(float(out[0].split(", ")[-1].split()[0]))


def test_vectorised_copies_step_in_lockstep_and_a_drawn_seed_is_not_drawn_again(monkeypatch):
    """gymnasium.make_vec (sync) runs copies of the task: a batch of observations, env i reset
    with seed s + i draws the single task's episode for that seed; a reset to a (seed, index)
    drawn before in the process reuses its draw (the draw is not made again)."""
    vec = gymnasium.make_vec(
        G.ENV_ID, num_envs=2, vectorization_mode="sync", style="office", detector="perfect", **SIZE
    )
    obs, info = vec.reset(seed=0)
    assert obs["rgb"].shape == (2, SIZE["height"], SIZE["width"], 3)
    single = make()
    for i in range(2):
        _, one = single.reset(seed=i)
        assert (info["room_seed"][i], info["target"][i]) == (one["room_seed"], one["target"])
    obs, reward, terminated, truncated, info = vec.step(np.array([7, 1]))
    assert reward.shape == (2,) and reward[0] < 0 and reward[1] < 0
    assert not terminated.any()
    vec.close()

    def no_draw(*a, **k):
        raise AssertionError("drew again")

    monkeypatch.setattr(G, "draw_episodes", no_draw)
    _, again = single.reset(seed=1)
    assert again["room_seed"] == one["room_seed"]
    single.close()


def test_a_draw_cache_serves_a_later_process_without_drawing(tmp_path, monkeypatch):
    """``draw_cache``: the first reset to a seed keeps its draw in the directory (the benchmark's
    draw cache); a later process (the kept draws forgotten) resets to it without checking a
    world, to the same episode, and the episode has no oracle view (the task has no oracle)."""
    env = make(draw_cache=tmp_path / "draws")
    env.reset(seed=11)
    first = env.unwrapped.episode
    env.close()
    assert first.first_view is None and len(list((tmp_path / "draws").glob("*.json"))) == 1
    monkeypatch.setattr(G, "_DRAWS", type(G._DRAWS)())

    def no_world(*_a, **_k):
        raise AssertionError("a world was checked: the cache was not read")

    monkeypatch.setattr("ctxsearch.agent.search.draw.draw_world", no_world)
    env = make(draw_cache=str(tmp_path / "draws"))
    env.reset(seed=11)
    assert env.unwrapped.episode == first and env.unwrapped.episode.start == first.start
    env.close()
    with pytest.raises(CtxsearchError, match="draw_cache must be a name or a path"):
        make(draw_cache=3)
