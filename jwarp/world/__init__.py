"""Worlds: simplex-noise occupancy grids, signed distance fields, world files, feasibility.

See :mod:`jwarp.world.sdf` for the grid convention (cell-centre ``limits``, metres,
negative inside obstacles) shared by every world constructor and by the collision kernels.
"""

from jwarp.world.feasibility import (
                                     feasible_fraction,
                                     feasible_simplex_world,
                                     fixed_spheres,
                                     random_configurations,
                                     robot_reach,
                                     robot_world_grid,
)
from jwarp.world.io import load_world, parse_world_spec, save_world
from jwarp.world.scene_file import (
                                     Scene,
                                     SceneOptions,
                                     exact_world,
                                     load_scene,
                                     scene_world,
                                     table_shelf_scene,
)
from jwarp.world.scenes import shelf_grasp_poses, shelf_world
from jwarp.world.sdf import (
                                     World,
                                     grid_geometry,
                                     world_from_mesh,
                                     world_from_occupancy,
                                     world_from_points,
)
from jwarp.world.self_pairs import (
                                     never_colliding_pairs,
                                     with_self_pairs,
                                     write_self_pairs,
)
from jwarp.world.simplex import (
                                     noise_grid,
                                     simplex_noise,
                                     simplex_occupancy,
                                     simplex_world,
)

__all__ = [
    "Scene", "SceneOptions", "exact_world", "feasible_fraction", "feasible_simplex_world",
    "fixed_spheres", "load_scene", "load_world", "never_colliding_pairs",
    "random_configurations", "robot_reach", "robot_world_grid", "save_world",
    "scene_world", "shelf_grasp_poses", "shelf_world", "simplex_world",
    "table_shelf_scene", "with_self_pairs", "world_from_mesh", "world_from_occupancy",
    "world_from_points", "write_self_pairs",
]
