"""Stores as older ctxsearch wrote them, made from a current store with the old DDL (tests)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

# The version-3 tables exactly as ctxsearch 3 created them (no day stamps).
V3_ROOMS = """CREATE TABLE rooms (
    run TEXT NOT NULL, style TEXT NOT NULL, seed INTEGER NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('started', 'done')),
    end_time REAL,
    PRIMARY KEY (run, style, seed)
)"""
V3_EXAMINATIONS = """CREATE TABLE examinations (
    id INTEGER PRIMARY KEY,
    run TEXT NOT NULL, style TEXT NOT NULL, room_seed INTEGER NOT NULL,
    object_id INTEGER NOT NULL, type TEXT NOT NULL,
    sim_time REAL NOT NULL, strategy TEXT NOT NULL, created REAL NOT NULL
)"""
V3_KEY = "CREATE UNIQUE INDEX examinations_key ON examinations (run, style, room_seed, object_id)"
V2_ROOM_INDEX = "CREATE INDEX examinations_room ON examinations (run, style, room_seed)"
EXAM_COLS = "id, run, style, room_seed, object_id, type, sim_time, strategy, created"


def as_version(path: Path, version: int) -> None:
    """Rewrite the (day-0, version-7) store at ``path`` as schema ``version`` (1 to 6) wrote
    it: the home_maps table goes (version 6), the room_contents table too (version 5), the
    views table too (version 4); the day columns go too; version 2 has no uniqueness key,
    version 1 no rooms.end_time."""
    conn = sqlite3.connect(path)
    conn.execute("PRAGMA foreign_keys = OFF")
    for table, below in (("home_maps", 7), ("room_contents", 6), ("views", 5)):
        conn.execute(f"DROP TABLE {table}")
        if version == below - 1:
            conn.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(version),))
            conn.commit()
            conn.execute("VACUUM")
            conn.close()
            return
    conn.execute("DROP INDEX examinations_key")
    conn.execute("DROP INDEX observations_pair")
    for t in ("observations", "examinations", "rooms"):
        conn.execute(f"ALTER TABLE {t} RENAME TO _new_{t}")
    conn.execute(V3_ROOMS)
    conn.execute(V3_EXAMINATIONS)
    conn.execute(V3_KEY if version == 3 else V2_ROOM_INDEX)
    conn.execute(
        "CREATE TABLE observations (\n"
        "    examination_id INTEGER NOT NULL REFERENCES examinations (id),\n"
        "    relation TEXT NOT NULL, type TEXT NOT NULL, related_id INTEGER NOT NULL\n)"
    )
    conn.execute("CREATE INDEX observations_pair ON observations (relation, type, examination_id)")
    conn.execute(
        "INSERT INTO rooms SELECT run, style, seed, status, end_time FROM _new_rooms WHERE day = 0"
    )
    conn.execute(f"INSERT INTO examinations SELECT {EXAM_COLS} FROM _new_examinations")
    conn.execute("INSERT INTO observations SELECT * FROM _new_observations")
    for t in ("observations", "examinations", "rooms"):
        conn.execute(f"DROP TABLE _new_{t}")
    if version == 1:
        conn.execute("ALTER TABLE rooms DROP COLUMN end_time")
    conn.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(version),))
    conn.commit()
    conn.execute("VACUUM")
    conn.close()
