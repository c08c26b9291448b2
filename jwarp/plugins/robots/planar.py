"""2D planar serial arms in the x-y plane: ``planar4`` (4 x 0.25 m) and ``planar5`` (5 x 0.2 m).

Both reach 1 m, have revolute joints about z with limits +-170 deg, a static ``base`` at
the origin, a static ``tcp`` at the tip (end effector ``tcp``), 3 spheres per link centred
in z = 0 and a point mass per link. Descriptions: ``planar4.json``, ``planar5.json``.
"""

from jwarp.plugins.registry import hookimpl
from jwarp.plugins.robots import load_builtin


@hookimpl
def jwarp_robots():
    return {"planar4": lambda: load_builtin("planar4.json"),
            "planar5": lambda: load_builtin("planar5.json")}
