"""Robot model: a tree of frames with DH rows, joints, masses, collision bodies.

The package: :mod:`jwarp.model.robot`."""

from jwarp.model.collision_pieces import CollisionPieces, ConvexPiece
from jwarp.model.robot import (
                               DH_PARAMS,
                               FRAME_KINDS,
                               FROZEN_NOTE,
                               JOINT_TYPES,
                               KAPPA_AXES,
                               MAX_LENGTH,
                               SCHEMA_NAME,
                               SCHEMA_VERSION,
                               Capsule,
                               Frame,
                               Joint,
                               LinearLimit,
                               Mass,
                               RobotModel,
                               RobotModelError,
                               SelfCollision,
                               Sphere,
                               freeze_joints,
                               frozen_joint_values,
                               validate,
)
from jwarp.model.sphere_relation import SphereRelation

__all__ = [
    "Capsule", "CollisionPieces", "ConvexPiece", "Frame", "Joint", "LinearLimit", "Mass", "RobotModelError", "SelfCollision",
    "Sphere", "SphereRelation", "freeze_joints", "frozen_joint_values", "validate",
]
