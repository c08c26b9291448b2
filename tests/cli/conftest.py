"""Fixtures of the CLI tests."""

from pathlib import Path

import pytest
from worlds import block_world_2d  # tests/worlds.py


@pytest.fixture(scope="module")
def block(tmp_path_factory) -> Path:
    """README's 2D block world for planar4 (:func:`worlds.block_world_2d`), as a .npz file."""
    from jwarp.world import save_world

    path = tmp_path_factory.mktemp("world") / "block.npz"
    save_world(block_world_2d(), path)
    return path
