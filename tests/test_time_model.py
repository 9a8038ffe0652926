"""The one time model: its vectorised forms equal its scalar ones, element by element."""

from __future__ import annotations

import math

import numpy as np

from ctxsearch.envs.robot_spec import TimeModel, wrap_angle, wrap_angles


def test_vectorised_forms_equal_the_scalar_ones():
    tm = TimeModel(drive_speed=0.7, turn_rate=0.9, pan_rate=1.3, tilt_rate=0.8, image_cost=0.4)
    rng = np.random.default_rng(0)
    y0, y1 = rng.uniform(-7, 7, 50), rng.uniform(-7, 7, 50)
    p0, t0, p1, t1 = (rng.uniform(-3, 3, 50) for _ in range(4))
    turns = tm.turn_times(y0, y1)
    heads = tm.head_times(p0, t0, p1, t1)
    for k in range(50):
        # numpy's sin/cos may differ from libm's in the last bit
        assert abs(turns[k] - tm.turn_time(y0[k], y1[k])) < 1e-12
        assert heads[k] == tm.head_time(p0[k], t0[k], p1[k], t1[k])
    np.testing.assert_allclose(wrap_angles(y0), [wrap_angle(a) for a in y0], rtol=0, atol=1e-12)
    assert tm.travel_time(1.4) == 2.0
    np.testing.assert_array_equal(tm.travel_time(np.array([0.7, 1.4])), [1.0, 2.0])


def test_estimates_use_the_models_rates():
    tm = TimeModel(drive_speed=0.5, turn_rate=math.pi / 2, image_cost=0.25)
    assert tm.leg_estimate(1.0) == 2.0 + 1.0  # drive + a quarter turn
    assert tm.leg_estimate(0.01) == 0.02  # too short to turn
    assert tm.leg_estimate(0.01, always_turn=True) == 0.02 + 1.0
    assert tm.looks_estimate(3, 0.5) == 3 * 0.75
    slow = TimeModel(drive_speed=0.25, turn_rate=math.pi / 4, image_cost=1.0)
    assert slow.leg_estimate(1.0) > tm.leg_estimate(1.0)
    assert slow.looks_estimate(3, 0.5) > tm.looks_estimate(3, 0.5)
