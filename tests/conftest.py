"""Shared pytest fixtures. Keep this small: module-specific helpers live in their test module."""

from __future__ import annotations

import pytest

from knowledge.catalog import Catalog, load_catalog


@pytest.fixture(scope="session")
def catalog() -> Catalog:
    """The project's default catalog (assets/types.toml)."""
    return load_catalog()


@pytest.fixture(scope="session")
def other_catalog() -> Catalog:
    """A tiny in-memory catalog whose fingerprint differs from the default one."""
    from knowledge.catalog import ObjectType, RelationSpec

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
