"""Shared pytest fixtures. Keep this small: module-specific helpers live in their test module."""

from __future__ import annotations

import pytest

from knowledge.catalog import Catalog, load_catalog


@pytest.fixture(scope="session")
def catalog() -> Catalog:
    """The project's default catalog (assets/types.toml)."""
    return load_catalog()
