"""Learning: torch costs (U_ik, U_path), basis point sets, IK networks (encodings,
twin-headed DenseNet-style network, checkpoints, label-free data, unsupervised and
supervised training), and the motion-planning network (plan_net, train_plan,
evaluate_plan). See docs/learning.md.

The exports are imported eagerly: the submodule ``jwarp.learn.train_ik`` shares its name
with the function ``train_ik``, and importing the function here is what keeps
``jwarp.learn.train_ik`` the function.
"""

from __future__ import annotations

from jwarp.learn.bps import BasisPointSet, basis_points, bps_encode
from jwarp.learn.checkpoint import (
                                    load_checkpoint,
                                    load_plan_checkpoint,
                                    read_checkpoint,
                                    save_checkpoint,
)
from jwarp.learn.encoding import JointCodec, frame_features
from jwarp.learn.evaluate_plan import evaluate_plan, format_plan_table
from jwarp.learn.ik_data import IKData, make_ik_data, make_worlds, sample_targets
from jwarp.learn.ik_net import IKNet, IKNetConfig
from jwarp.learn.plan_net import (
                                    AXIS_SYMMETRIES,
                                    AxisSymmetry,
                                    PlanNet,
                                    PlanNetConfig,
                                    axis_symmetries,
)
from jwarp.learn.torch_costs import ik_objective, u_ik, u_path
from jwarp.learn.train_ik import (
                                    IKTrainer,
                                    TrainIKOptions,
                                    ik_loss,
                                    train_ik,
                                    train_ik_supervised,
)
from jwarp.learn.train_plan import (
                                    PlanSamples,
                                    TrainPlanOptions,
                                    clean,
                                    extend,
                                    improve,
                                    make_plan_data,
                                    train_plan,
)

__all__ = [
    "BasisPointSet", "basis_points", "bps_encode", "load_checkpoint", "read_checkpoint",
    "save_checkpoint", "JointCodec", "frame_features", "IKData", "make_ik_data",
    "make_worlds", "sample_targets", "IKNet", "IKNetConfig", "u_ik", "u_path", "IKTrainer",
    "TrainIKOptions", "ik_loss", "train_ik", "train_ik_supervised", "load_plan_checkpoint",
    "evaluate_plan", "format_plan_table", "AxisSymmetry", "PlanNet", "PlanNetConfig",
    "axis_symmetries", "PlanSamples", "TrainPlanOptions", "clean", "extend", "improve",
    "make_plan_data", "train_plan",
]
