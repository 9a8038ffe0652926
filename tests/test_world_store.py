"""A world's model made once (envs.world_store): the same model as the composer task builds, read
back from memory or disk bit for bit, and any file that is not that world a miss."""

from __future__ import annotations

import json
from dataclasses import replace

import mujoco
import numpy as np
import pytest
from dm_control import mjcf

from ctxsearch.envs import world_store
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.envs.task import RoomTask
from ctxsearch.envs.world import World
from ctxsearch.knowledge.catalog import load_catalog


@pytest.fixture(scope="module")
def catalog():
    return load_catalog()


def _mjb(model: mujoco.MjModel) -> bytes:
    buf = np.zeros(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, buf)
    return buf.tobytes()


def _task_model(layout, catalog, spec=None) -> tuple[str, mujoco.MjModel]:
    task = RoomTask(catalog, layout=layout, spec=spec)
    task.initialize_episode_mjcf(np.random.RandomState(0))
    xml = task.root_entity.mjcf_model.to_xml_string()
    return xml, mjcf.Physics.from_mjcf_model(task.root_entity.mjcf_model).model.ptr


ROOMS_AND_HOUSES = ("office", "bedroom", "biology_lab", "kitchen", "living_room", "apartment",
                    "family_house", "office_floor")  # fmt: skip


def _layouts(catalog):
    for k, style in enumerate(ROOMS_AND_HOUSES):
        yield generate_layout(resolve_style(style, catalog), k, catalog, day=k % 2)
    lay = generate_layout(resolve_style("apartment", catalog), 4, catalog)
    yield lay.without({lay.objects[-1].id, lay.objects[0].id})  # an episode's layout
    yield replace(lay, objects=())


def test_the_world_xml_is_the_composer_tasks_byte_for_byte(catalog):
    """The shell (arena and robot) and the objects are written as text: the same bytes as the
    composer task's elements give, in every room and house style, so the same model."""
    for layout in _layouts(catalog):
        xml, model = _task_model(layout, catalog)
        mine, robot_xml = world_store.build_xml(layout, catalog, RobotSpec())
        assert mine == xml
        world_store.forget()
        got = world_store.world_model(layout, catalog, RobotSpec(), disk=False)
        assert _mjb(got.model) == _mjb(model)
        assert _mjb(got.copy()) == _mjb(model)
    spec = replace(RobotSpec(), camera_height=1.1)
    assert world_store.build_xml(layout, catalog, spec)[0] == _task_model(layout, catalog, spec)[0]


def _path(layout, catalog):
    key = world_store.world_key(layout, catalog, RobotSpec())
    return key, world_store.cache_dir() / "worlds" / f"{key}.json"


def test_a_world_read_back_from_disk_is_the_same_model_and_world(catalog, tmp_path, monkeypatch):
    monkeypatch.setenv("CTXSEARCH_CACHE_DIR", str(tmp_path))
    layout = generate_layout(resolve_style("apartment", catalog), 7, catalog)
    world_store.forget()
    made = world_store.world_model(layout, catalog, RobotSpec())
    key, path = _path(layout, catalog)
    assert path.is_file()
    world_store.forget()  # a later process: the file, not the memory
    read = world_store.load(path, key, layout, catalog)
    assert read is not None and _mjb(read.model) == _mjb(made.model)
    assert read.xml == made.xml and read.robot_xml == made.robot_xml
    frames = []
    for _ in range(2):
        with World(layout, catalog) as w:
            w.reset_pose(RobotPose(0.0, 0.0, 0.5, 0.2, -0.3))
            w.drive(np.array([[0.3, 0.2]]), final_yaw=1.0)
            f = w.capture(depth=True)
            frames.append((f.instance_ids.tobytes(), f.depth.tobytes(), w._d.qpos.tobytes()))
            assert w.physics.bind(w.task.robot.joints).qposadr.tolist() == w._qadr.tolist()
        world_store.forget()
    assert frames[0] == frames[1]


def _rewrite(path, **changes):
    doc = json.loads(path.read_text())
    doc.update(changes)
    doc["sha256"] = world_store._digest(doc["xml"], doc["robot_xml"])
    path.write_text(json.dumps(doc))


def test_a_file_that_is_not_the_world_asked_for_is_a_miss(catalog, tmp_path, monkeypatch):
    monkeypatch.setenv("CTXSEARCH_CACHE_DIR", str(tmp_path))
    layout = generate_layout(resolve_style("office", catalog), 3, catalog)
    world_store.forget()
    good = world_store.world_model(layout, catalog, RobotSpec())
    key, path = _path(layout, catalog)
    original = path.read_bytes()
    doc = json.loads(original)
    moved = doc["xml"].replace(
        'name="wall_north" class="/" type="box" group="0" size="',
        'name="wall_north" class="/" type="box" group="0" size="0.5 ',
        1,
    )
    other = generate_layout(resolve_style("office", catalog), 4, catalog)
    hostile = [
        original[: len(original) // 2],  # a truncated write
        original.replace(b"objects/obj1_", b"objects/obj9_", 1),  # an edit: digest no longer fits
        b"\x00\xff" * 100,
        b"[]",
    ]
    for data in hostile:
        path.write_bytes(data)
        assert world_store.load(path, key, layout, catalog) is None
    # consistent files (the digest recomputed) of another world, or with a wall moved or added
    for xml in (
        world_store.build_xml(other, catalog, RobotSpec())[0],
        moved,
        doc["xml"].replace("<worldbody>", '<worldbody>\n<geom name="x" type="box" size="1 1 1"/>'),
        doc["xml"].replace('zfar="6"', 'zfar="7"'),
    ):
        path.write_bytes(original)
        _rewrite(path, xml=xml)
        assert world_store.load(path, key, layout, catalog) is None
    path.write_bytes(original)
    _rewrite(path, key="0" * 32)
    assert world_store.load(path, key, layout, catalog) is None
    # a miss is built again and the file replaced
    path.write_bytes(b"junk")
    world_store.forget()
    again = world_store.world_model(layout, catalog, RobotSpec())
    assert _mjb(again.model) == _mjb(good.model) and path.read_bytes() == original


def test_a_changed_layout_catalog_or_robot_is_another_world(catalog):
    layout = generate_layout(resolve_style("office", catalog), 3, catalog)
    key = world_store.world_key(layout, catalog, RobotSpec())
    o = layout.objects[0]
    nudged = replace(o, position=(o.position[0] + 1e-9, *o.position[1:]))
    assert (
        world_store.world_key(
            replace(layout, objects=(nudged, *layout.objects[1:])), catalog, RobotSpec()
        )
        != key
    )
    assert world_store.world_key(layout, catalog, replace(RobotSpec(), fovy_deg=50.0)) != key
    t = catalog.types[0]
    recoloured = replace(catalog, types=(replace(t, color=(0.1, 0.2, 0.3)), *catalog.types[1:]))
    assert world_store.world_key(layout, recoloured, RobotSpec()) != key
    assert world_store.world_key(layout, catalog, RobotSpec()) == key


def test_the_memory_keeps_a_bounded_number_of_worlds(catalog):
    world_store.forget()
    style = resolve_style("office", catalog)
    for s in range(world_store.MEMO_WORLDS + 3):
        world_store.world_model(
            generate_layout(style, s, catalog), catalog, RobotSpec(), disk=False
        )
    assert len(world_store._worlds) == world_store.MEMO_WORLDS
