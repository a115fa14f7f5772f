#include "control/kinematics.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/check.h"

namespace toolbench::control {

KinematicChain::KinematicChain(const robot::RobotModel& model, std::string_view base_link,
                               std::string_view tip_link)
    : base_link_(base_link), tip_link_(tip_link), num_model_q_(model.num_q()) {
  const int base = model.LinkIndex(base_link);
  const int tip = model.LinkIndex(tip_link);
  // Walk tip -> base, then reverse, so segments come out root-to-tip.
  std::vector<int> path_joints;
  int link = tip;
  while (link != base) {
    const int joint = model.links[link].parent_joint;
    if (joint < 0) {
      ThrowInvalid("KinematicChain: link '", base_link, "' is not an ancestor of '", tip_link, "' in robot '",
                   model.name, "'");
    }
    path_joints.push_back(joint);
    link = model.joints[joint].parent_link;
  }
  std::reverse(path_joints.begin(), path_joints.end());

  Eigen::Isometry3d X_pending = Eigen::Isometry3d::Identity();  // fixed transforms since the last movable joint
  std::vector<double> lower;
  std::vector<double> upper;
  for (int j : path_joints) {
    const robot::Joint& joint = model.joints[j];
    if (!joint.movable()) {
      X_pending = X_pending * joint.X_PJ;
      continue;
    }
    Segment segment{X_pending * joint.X_PJ, joint.axis.normalized(), joint.type == robot::Joint::Type::kPrismatic};
    for (int k = 0; k < 3; ++k) {
      if (std::abs(std::abs(segment.axis[k]) - 1.0) < 1e-12) {
        segment.unit_axis = k;
        segment.axis_sign = segment.axis[k] > 0 ? 1.0 : -1.0;
        segment.axis = segment.axis_sign * Eigen::Vector3d::Unit(k);
      }
    }
    segments_.push_back(segment);
    X_pending.setIdentity();
    q_indices_.push_back(joint.q_index);
    joint_names_.push_back(joint.name);
    const bool unbounded = joint.type == robot::Joint::Type::kContinuous;
    lower.push_back(unbounded ? -std::numeric_limits<double>::infinity() : joint.lower);
    upper.push_back(unbounded ? std::numeric_limits<double>::infinity() : joint.upper);
  }
  X_LT_ = X_pending;
  lower_ = Eigen::Map<const Eigen::VectorXd>(lower.data(), static_cast<Eigen::Index>(lower.size()));
  upper_ = Eigen::Map<const Eigen::VectorXd>(upper.data(), static_cast<Eigen::Index>(upper.size()));
}

Eigen::VectorXd KinematicChain::ChainQ(const Eigen::VectorXd& q_model) const {
  if (q_model.size() != num_model_q_) {
    ThrowInvalid("KinematicChain::ChainQ: q has ", q_model.size(), " entries, expected ", num_model_q_);
  }
  Eigen::VectorXd q_chain(num_joints());
  for (int i = 0; i < num_joints(); ++i) q_chain[i] = q_model[q_indices_[i]];
  return q_chain;
}

Eigen::VectorXd KinematicChain::ModelQ(const Eigen::VectorXd& q_model, const Eigen::VectorXd& q_chain) const {
  if (q_model.size() != num_model_q_ || q_chain.size() != num_joints()) {
    ThrowInvalid("KinematicChain::ModelQ: got q_model with ", q_model.size(), " and q_chain with ", q_chain.size(),
                 " entries, expected ", num_model_q_, " and ", num_joints());
  }
  Eigen::VectorXd out = q_model;
  for (int i = 0; i < num_joints(); ++i) out[q_indices_[i]] = q_chain[i];
  return out;
}

Eigen::Isometry3d KinematicChain::TipPose(const Eigen::VectorXd& q_model) const {
  if (q_model.size() == num_model_q_ && !q_model.allFinite()) {
    ThrowInvalid("KinematicChain::TipPose: q has a non-finite entry");
  }
  Eigen::Isometry3d X_BT;
  Evaluate(ChainQ(q_model), &X_BT, nullptr);
  return X_BT;
}

ChainJacobian KinematicChain::Jacobian(const Eigen::VectorXd& q_model) const {
  if (q_model.size() == num_model_q_ && !q_model.allFinite()) {
    ThrowInvalid("KinematicChain::Jacobian: q has a non-finite entry");
  }
  Eigen::Isometry3d X_BT;
  ChainJacobian J(6, num_joints());
  Evaluate(ChainQ(q_model), &X_BT, &J);
  return J;
}

void KinematicChain::Evaluate(const Eigen::VectorXd& q_chain, Eigen::Isometry3d* X_BT, ChainJacobian* J_BT) const {
  TOOLBENCH_DEMAND(q_chain.size() == num_joints());
  TOOLBENCH_DEMAND(X_BT != nullptr);
  const int n = num_joints();
  if (J_BT != nullptr && J_BT->cols() != n) J_BT->resize(6, n);
  // Forward pass: store each joint's axis and origin in B (columns of J as scratch), then
  // fill the linear rows once the tip position is known. Rotating about the axis leaves the
  // axis unchanged, so the axis in B can be taken from the joint frame before its motion.
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  for (int i = 0; i < n; ++i) {
    const Segment& s = segments_[i];
    X = X * s.X_PJ;
    const Eigen::Vector3d z_B = X.linear() * s.axis;
    if (J_BT != nullptr) {
      J_BT->col(i).head<3>() = X.translation();  // origin for now; replaced below
      J_BT->col(i).tail<3>() = z_B;
    }
    if (s.prismatic) {
      X.translate(s.axis * q_chain[i]);
    } else if (s.unit_axis >= 0) {
      // About a coordinate axis k: columns a and b (the other two, cyclic) turn in their plane.
      const double angle = s.axis_sign * q_chain[i];
      const double c = std::cos(angle);
      const double sn = std::sin(angle);
      const int a = (s.unit_axis + 1) % 3;
      const int b = (s.unit_axis + 2) % 3;
      const Eigen::Vector3d col_a = X.linear().col(a);
      const Eigen::Vector3d col_b = X.linear().col(b);
      X.linear().col(a) = c * col_a + sn * col_b;
      X.linear().col(b) = c * col_b - sn * col_a;
    } else {
      X.rotate(Eigen::AngleAxisd(q_chain[i], s.axis));
    }
  }
  *X_BT = X * X_LT_;
  if (J_BT == nullptr) return;
  const Eigen::Vector3d p_BT = X_BT->translation();
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d z_B = J_BT->col(i).tail<3>();
    if (segments_[i].prismatic) {
      J_BT->col(i).head<3>() = z_B;
      J_BT->col(i).tail<3>().setZero();
    } else {
      const Eigen::Vector3d p_BO = J_BT->col(i).head<3>();
      J_BT->col(i).head<3>() = z_B.cross(p_BT - p_BO);
    }
  }
}

std::vector<std::string> RightArmJointNames() {
  return {"torso_pitch",   "torso_roll",     "torso_yaw",     "r_shoulder_pitch", "r_shoulder_roll",
          "r_shoulder_yaw", "r_elbow",       "r_wrist_prosup", "r_wrist_pitch",   "r_wrist_yaw"};
}

KinematicChain MakeRightArmChain(const robot::RobotModel& model, std::string_view tip_link) {
  if (model.links.empty()) ThrowInvalid("MakeRightArmChain: robot '", model.name, "' has no links");
  const std::vector<std::string> expected = RightArmJointNames();
  for (const std::string& name : expected) {
    const bool found = std::any_of(model.joints.begin(), model.joints.end(),
                                   [&](const robot::Joint& j) { return j.name == name && j.movable(); });
    if (!found) {
      ThrowInvalid("MakeRightArmChain: robot '", model.name, "' has no movable joint '", name,
                   "' (the 10-DOF arm chain needs torso_pitch/roll/yaw and r_shoulder_pitch .. r_wrist_yaw)");
    }
  }
  KinematicChain chain(model, model.links.front().name, tip_link);
  if (chain.joint_names() != expected) {
    std::string got;
    for (const std::string& name : chain.joint_names()) got += (got.empty() ? "" : ", ") + name;
    ThrowInvalid("MakeRightArmChain: the path from '", model.links.front().name, "' to '", tip_link,
                 "' has joints [", got, "], expected the 10-DOF torso + right arm chain");
  }
  return chain;
}

Eigen::Vector3d OrientationError(const Eigen::Matrix3d& R_target, const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R_target * R.transpose());
  return aa.angle() * aa.axis();
}

}  // namespace toolbench::control
