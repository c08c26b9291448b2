"""DLR Agile Justin upper body: 19 DoF, 27 frames, coupled torso joint, 21 masses, 53 spheres.

Numbers: the published ones (``shared/robots/justin19.json``) in jwarp's schema,
``justin19.json`` beside this module.
"""

from jwarp.plugins.registry import hookimpl
from jwarp.plugins.robots import load_builtin


@hookimpl
def jwarp_robots():
    return {"justin19": lambda: load_builtin("justin19.json")}
