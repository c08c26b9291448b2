"""Agile Justin's right arm on a fixed base: 7 DoF, 9 frames, 8 masses, 14 spheres.

The numbers are justin19's (frames ``right_base`` .. ``right_tcp``, joints ``right_1`` ..
``right_7``, their masses, spheres and self-collision group) copied exactly into
``arm7.json`` beside this module; ``right_base`` is the static root, standing upright
0.5 m above the world origin (identity rotation). End effectors ``right_tcp`` and ``tcp``.
"""

from jwarp.plugins.registry import hookimpl
from jwarp.plugins.robots import load_builtin


@hookimpl
def jwarp_robots():
    return {"arm7": lambda: load_builtin("arm7.json")}
