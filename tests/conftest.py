"""Shared pytest fixtures. Keep this small: module-specific helpers live in their test module."""

from __future__ import annotations

import os

# Off-screen rendering through EGL must be chosen before the first mujoco import, whichever test
# module pytest happens to import first.
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
# The tests keep what they cache (agent.search.truth_store) in a folder of their own, never in the
# user's cache; subprocesses of the CLI inherit it.
if "CTXSEARCH_CACHE_DIR" not in os.environ:
    import tempfile

    os.environ["CTXSEARCH_CACHE_DIR"] = tempfile.mkdtemp(prefix="ctxsearch-test-cache-")

import pytest  # noqa: E402

from ctxsearch.knowledge.catalog import Catalog, load_catalog  # noqa: E402


@pytest.fixture(scope="session")
def catalog() -> Catalog:
    """The project's default catalog (assets/types.toml)."""
    return load_catalog()


@pytest.fixture(scope="session")
def other_catalog() -> Catalog:
    """A tiny in-memory catalog whose fingerprint differs from the default one."""
    from ctxsearch.knowledge.catalog import ObjectType, RelationSpec

    u, v = (-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)
    return Catalog(
        (
            ObjectType(
                "Crate",
                "furniture",
                "box",
                (1, 1, 1),
                (1, 1, 1),
                (0.5, 0.4, 0.3),
                50,
                8.0,
                (RelationSpec("ON-TOP-OF-CRATE", "Crate", u, v),),
            ),
            ObjectType(
                "Cup", "object", "mug", (0.1, 0.1, 0.1), (0.1, 0.1, 0.1), (1, 1, 1), 20, 4.0, ()
            ),
        ),
        path="<other catalog>",
    )


@pytest.fixture()
def desk_cup_store(catalog):
    """A factory: ``desk_cup_store(path, rooms)`` writes a store in which each of ``rooms``
    office rooms had one desk with a cup on top (run 't'), and returns ``path``."""
    from ctxsearch.knowledge.store import EvidenceStore

    def make(path, rooms: int = 5):
        with EvidenceStore.open(path, catalog, create=True) as s:
            for i in range(rooms):
                s.record(
                    run="t",
                    style="office",
                    room_seed=i,
                    object_id=1,
                    ref_type="Desk",
                    sim_time=0.0,
                    strategy="t",
                    related=[("ON-TOP-OF-DESK", "Cup", 2)],
                )
        return path

    return make


@pytest.fixture(scope="session")
def small_rrd(tmp_path_factory):
    """A small rerun recording (two points), written by rerun's SDK."""
    import rerun as rr

    path = tmp_path_factory.mktemp("rrd") / "small.rrd"
    rec = rr.RecordingStream("ctxsearch-small-recording")
    rec.save(str(path))
    rec.log("world/points", rr.Points3D([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]))
    rec.flush()
    del rec
    return path


# The test files that take longest (``pytest --durations=30`` on a 2-core machine), started first
# so that with ``make test``'s workers (pytest-xdist, a file per worker at a time) no long file
# is left to run alone at the end. Only the order changes; every test runs.
SLOW_FILES_FIRST = (
    "test_search_protocol.py",
    "test_sweep.py",
    "test_bench_curve.py",
    "test_journal.py",
    "test_gym_env.py",
    "test_search.py",
    "test_cli_search.py",
    "test_acquisition.py",
    "test_mapping.py",
    "test_references.py",
)


def pytest_collection_modifyitems(items):
    """Put the tests of ``SLOW_FILES_FIRST`` first, in that order (a stable sort)."""
    rank = {name: i for i, name in enumerate(SLOW_FILES_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
