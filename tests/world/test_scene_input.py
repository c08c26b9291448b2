"""Scene input as tools write it (MoveIt frames without headers, full robot states with
gripper joints the model lacks or fixes), bad scenes that fail with a ValueError naming
the object and the problem, and grids whose cell count would overflow."""

from __future__ import annotations

import numpy as np
import pytest

from jwarp.world.scene_file import Scene, SceneOptions, load_scene, scene_world
from jwarp.world.sdf import MAX_GRID_CELLS, grid_geometry

TABLE_SHELF = "examples/scenes/table_shelf.yaml"


# ------------------------------------------------------------------ grid sizes
@pytest.mark.parametrize("voxel", [1e-300, 1e-320, 1e-4])
def test_grid_geometry_refuses_too_many_cells(voxel):
    with pytest.raises(ValueError, match=r"voxel_size: .* needs a grid of .* cells, more than "
                                         r"the 2\*\*31"):
        grid_geometry(3, limits=[[0, 1], [0, 1], [0, 1]], voxel_size=voxel)


def test_grid_geometry_refuses_a_huge_shape():
    with pytest.raises(ValueError, match=r"shape needs a grid of 70000 x 70000 x 1000"):
        grid_geometry(3, shape=(70000, 70000, 1000), voxel_size=0.1)
    s, _, _ = grid_geometry(3, limits=[[0, 1], [0, 1], [0, 1]], voxel_size=0.01)
    assert s == (101, 101, 101)


@pytest.mark.parametrize("voxel", [0.0, -0.01, float("nan"), float("inf")])
def test_grid_geometry_refuses_bad_voxels(voxel):
    with pytest.raises(ValueError, match="voxel_size: expected a positive number"):
        grid_geometry(3, limits=[[0, 1], [0, 1], [0, 1]], voxel_size=voxel)


@pytest.fixture(scope="module")
def table_shelf() -> Scene:
    from pathlib import Path

    return load_scene(Path(__file__).resolve().parents[2] / TABLE_SHELF)


@pytest.mark.parametrize("voxel", [1e-300, 1e-320, 5e-4])
def test_scene_world_refuses_overflowing_voxels(table_shelf, voxel):
    """It used to wrap the int64 cell count around to a 2 x 2 x 2 grid."""
    with pytest.raises(ValueError, match=r"voxel_size: .* needs a grid of .* cells, more than "
                                         r"the 2\*\*31"):
        scene_world(table_shelf, SceneOptions(voxel_size=voxel))


@pytest.mark.parametrize("voxel", [0.0, -1.0, float("nan"), float("inf")])
def test_scene_world_refuses_bad_voxels(table_shelf, voxel):
    with pytest.raises(ValueError, match="voxel_size: expected a positive number"):
        scene_world(table_shelf, SceneOptions(voxel_size=voxel))


def test_scene_world_refuses_grids_beyond_memory(table_shelf, monkeypatch):
    import jwarp.memory

    monkeypatch.setattr(jwarp.memory, "available_memory", lambda: 10 ** 6)
    with pytest.raises(ValueError, match=r"voxel_size: 0.02 m .* needs a grid of 51 x 95 x 66 "
                                         r"= 3.198e\+05 cells, about 10.2 MB of memory, more "
                                         r"than the 1.0 MB available"):
        scene_world(table_shelf, SceneOptions(voxel_size=0.02))
    assert 51 * 95 * 66 < MAX_GRID_CELLS
