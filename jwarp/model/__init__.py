"""Robot model: a tree of frames with DH rows, joints, masses, collision bodies.

The package: :mod:`jwarp.model.robot`."""

from jwarp.model.robot import (Capsule, DH_PARAMS, FRAME_KINDS, FROZEN_NOTE, Frame, JOINT_TYPES,
                               Joint, KAPPA_AXES, LinearLimit, MAX_LENGTH, Mass, RobotModel,
                               RobotModelError, SCHEMA_NAME, SCHEMA_VERSION, SelfCollision,
                               Sphere, freeze_joints, frozen_joint_values, validate)
from jwarp.model.collision_pieces import CollisionPieces, ConvexPiece
from jwarp.model.sphere_relation import SphereRelation

__all__ = [
    "Capsule", "CollisionPieces", "ConvexPiece", "Frame", "Joint", "LinearLimit", "Mass", "RobotModelError", "SelfCollision",
    "Sphere", "SphereRelation", "freeze_joints", "frozen_joint_values", "validate",
]
