"""Robot model: a tree of frames with DH rows, joints, masses, collision bodies.

The package: :mod:`jwarp.model.robot` (the model), :mod:`jwarp.model.parts` (its parts),
:mod:`jwarp.model.schema` (the JSON schema and the checks), :mod:`jwarp.model.freeze` (frozen
joints)."""

from jwarp.model.collision_pieces import CollisionPieces, ConvexPiece
from jwarp.model.freeze import FROZEN_NOTE, freeze_joints, frozen_joint_values
from jwarp.model.parts import Capsule, Frame, Joint, LinearLimit, Mass, SelfCollision, Sphere
from jwarp.model.robot import RobotModel
from jwarp.model.schema import (
    DH_PARAMS,
    FRAME_KINDS,
    JOINT_TYPES,
    KAPPA_AXES,
    MAX_LENGTH,
    SCHEMA_NAME,
    SCHEMA_VERSION,
    RobotModelError,
    validate,
)
from jwarp.model.sphere_relation import SphereRelation

__all__ = [
    "Capsule", "CollisionPieces", "ConvexPiece", "Frame", "Joint", "LinearLimit", "Mass", "RobotModelError", "SelfCollision",
    "Sphere", "SphereRelation", "freeze_joints", "frozen_joint_values", "validate",
]
