"""Sweeps: the same results serially and on a local Ray, errors as one line, no Ray import for
one worker."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from knowledge.errors import CtxsearchError
from scripts.sweep import run_units

ROOT = Path(__file__).resolve().parents[1]


def square_with_pid(x: int) -> dict:
    import os

    return {"x": x, "y": x * x, "pid": os.getpid()}


def refuse_three(x: int) -> int:
    if x == 3:
        raise CtxsearchError("unit 3: bad input")
    return x


def test_one_worker_is_a_loop_without_ray():
    code = (
        "import sys; from scripts.sweep import run_units; "
        "from tests.test_sweep import square_with_pid as f; "
        "r = run_units(f, [1, 2, 3], progress=False); assert [u['y'] for u in r] == [1, 4, 9]; "
        "assert 'ray' not in sys.modules"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


@pytest.mark.slow
def test_two_workers_give_the_serial_results_in_order():
    units = list(range(8))
    serial = run_units(square_with_pid, units, progress=False)
    parallel = run_units(square_with_pid, units, workers=2, progress=False)
    strip = [{k: v for k, v in d.items() if k != "pid"} for d in parallel]
    assert strip == [{k: v for k, v in d.items() if k != "pid"} for d in serial]
    assert {d["pid"] for d in parallel}.isdisjoint({d["pid"] for d in serial})  # other processes
    with pytest.raises(CtxsearchError, match="unit 3: bad input"):
        run_units(refuse_three, units, workers=2, progress=False)


def test_bad_worker_count():
    with pytest.raises(CtxsearchError, match="at least 1"):
        run_units(square_with_pid, [1], workers=0)
