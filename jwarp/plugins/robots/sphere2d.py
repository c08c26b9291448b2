"""2-DoF point robot in the plane: one sphere (r = 0.05 m) moved by prismatic x and y joints.

Joints ``x``, ``y`` in [-1, 1] m; the end effector ``point`` sits at ``(q_x, q_y, 0)`` with
the world's orientation. Description: ``sphere2d.json``.
"""

from jwarp.plugins.registry import hookimpl
from jwarp.plugins.robots import load_builtin


@hookimpl
def jwarp_robots():
    return {"sphere2d": lambda: load_builtin("sphere2d.json")}
