"""Four-finger hand (thumb, index, middle, ring): 12 actuated joints, 16 driven frames, 25 frames.

Per finger: abduction, two active flexion joints and a passive distal flexion joint coupled
1:1 to the second one; capsule fingertips for contact calibration; end effectors
``thumb_tip``, ``index_tip``, ``middle_tip``, ``ring_tip``. Human-like dimensions, documented
in ``hand4.json`` (description and notes).
"""

from jwarp.plugins.registry import hookimpl
from jwarp.plugins.robots import load_builtin


@hookimpl
def jwarp_robots():
    return {"hand4": lambda: load_builtin("hand4.json")}
