"""Independent units of a sweep, run serially or as Ray tasks (``--workers N``, ``--ray-address``).

``run_units(fn, units)`` calls ``fn(unit)`` for every unit and returns the results in unit
order, whatever order they finish in, so a sweep's output does not depend on how it was run.
With one worker and no cluster address nothing but a loop runs and Ray is never imported; with
``workers > 1`` a local Ray is started for the call (that many CPUs) and shut down after; with
``ray_address`` the units go to an existing cluster (``ray start --head`` somewhere, then
``--ray-address HOST:PORT``, or ``auto``). ``fn`` must be a module-level function and units and
results plain data (numbers, strings, lists, dicts): they travel between processes. A unit that
raises a CtxsearchError ends the sweep with that error (one line, as everywhere).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import TypeVar

from knowledge.errors import CtxsearchError

U = TypeVar("U")
R = TypeVar("R")
# What a worker process needs to render off-screen like the driver.
WORKER_ENV = ("MUJOCO_GL", "PYOPENGL_PLATFORM")


def _progress(total: int, desc: str, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="unit", disable=not enabled, leave=False)


def run_units(
    fn: Callable[[U], R],
    units: Sequence[U],
    *,
    workers: int = 1,
    ray_address: str | None = None,
    desc: str = "units",
    progress: bool = True,
) -> list[R]:
    """``[fn(u) for u in units]``, serially or as Ray tasks (see the module docstring), with a
    progress bar over finished units."""
    if workers < 1:
        raise CtxsearchError(f"--workers must be at least 1, got {workers}")
    if workers == 1 and not ray_address:
        out = []
        with _progress(len(units), desc, progress) as bar:
            for u in units:
                out.append(fn(u))
                bar.update(1)
        return out
    return _run_on_ray(fn, units, workers, ray_address, desc, progress)


def _run_on_ray(fn, units, workers, ray_address, desc, progress):
    # Imported here, not at the top: Ray costs ~1.5 s to import and one-worker runs never need it.
    import ray
    from ray.exceptions import RayTaskError

    env = {k: os.environ[k] for k in WORKER_ENV if k in os.environ}
    started = not ray.is_initialized()
    if started:
        kwargs = dict(
            runtime_env={"env_vars": env},
            log_to_driver=False,
            configure_logging=False,
            include_dashboard=False,
        )
        try:
            if ray_address:
                ray.init(address=ray_address, **kwargs)
            else:
                ray.init(num_cpus=workers, **kwargs)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = ray_address or "a local Ray"
            raise CtxsearchError(f"cannot start {where}: {' '.join(str(exc).split())}") from None
    try:
        task = ray.remote(num_cpus=1, max_retries=0)(fn)
        pending = {task.remote(u): i for i, u in enumerate(units)}
        out: list = [None] * len(units)
        with _progress(len(units), desc, progress) as bar:
            while pending:
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    try:
                        out[pending.pop(ref)] = ray.get(ref)
                    except RayTaskError as exc:
                        cause = exc.cause if isinstance(exc.cause, CtxsearchError) else None
                        if cause is not None:
                            raise cause from None
                        raise
                    bar.update(1)
        return out
    finally:
        if started:
            ray.shutdown()
