#pragma once

#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "robot/robot_model.h"

namespace toolbench::control {

/// 6 x n geometric Jacobian: rows 0-2 map joint rates to the tip's linear velocity, rows 3-5 to
/// its angular velocity, both expressed in the chain's base frame B.
using ChainJacobian = Eigen::Matrix<double, 6, Eigen::Dynamic>;

/// The serial chain of a RobotModel from a base link B to a tip link T: the movable joints on the
/// path (root-to-tip order), their q indices in the full model vector and limits, forward
/// kinematics X_BT and the analytic geometric Jacobian. Fixed joints on the path are folded into
/// constant transforms at construction, so evaluation is one pass of n joint motions.
/// A constant description: cheap to copy, thread-safe to share.
class KinematicChain {
 public:
  /// Builds the chain from `base_link` to `tip_link`. Throws std::invalid_argument naming the
  /// link when either is unknown, or when `base_link` is not an ancestor of (or equal to)
  /// `tip_link`.
  KinematicChain(const robot::RobotModel& model, std::string_view base_link, std::string_view tip_link);

  /// Number of movable joints on the path (chain DOF).
  int num_joints() const { return static_cast<int>(q_indices_.size()); }
  /// Size of the full model joint vector this chain reads from.
  int num_model_q() const { return num_model_q_; }
  const std::string& base_link() const { return base_link_; }
  const std::string& tip_link() const { return tip_link_; }
  /// Index of each chain joint in the full model q, root-to-tip order.
  const std::vector<int>& q_indices() const { return q_indices_; }
  /// Names of the chain joints, root-to-tip order.
  const std::vector<std::string>& joint_names() const { return joint_names_; }
  /// Position limits of the chain joints [rad or m] (continuous joints: +-inf).
  const Eigen::VectorXd& lower() const { return lower_; }
  const Eigen::VectorXd& upper() const { return upper_; }

  /// Chain joint values (num_joints() entries) picked from a full model q. Throws
  /// std::invalid_argument when q does not have num_model_q() entries.
  Eigen::VectorXd ChainQ(const Eigen::VectorXd& q_model) const;
  /// Writes chain joint values into a copy of `q_model` and returns it. Throws
  /// std::invalid_argument on wrong sizes.
  Eigen::VectorXd ModelQ(const Eigen::VectorXd& q_model, const Eigen::VectorXd& q_chain) const;

  /// Pose X_BT of the tip in the base frame for a full model q (num_model_q() entries, finite).
  /// Throws std::invalid_argument on a wrong size or non-finite entry.
  Eigen::Isometry3d TipPose(const Eigen::VectorXd& q_model) const;
  /// Geometric Jacobian of the tip (see ChainJacobian) for a full model q; columns follow
  /// joint_names(). Throws like TipPose.
  ChainJacobian Jacobian(const Eigen::VectorXd& q_model) const;

  /// Hot-loop form on chain values (num_joints() entries, not checked beyond a DEMAND on the
  /// size): writes X_BT and, when `J_BT` is not null, the Jacobian into a preallocated 6 x n
  /// matrix (resized only if its size is wrong). Does not allocate when sizes are right.
  void Evaluate(const Eigen::VectorXd& q_chain, Eigen::Isometry3d* X_BT, ChainJacobian* J_BT) const;

 private:
  struct Segment {
    Eigen::Isometry3d X_PJ;   // joint frame in the previous segment's moving frame (fixed joints folded in)
    Eigen::Vector3d axis;     // unit, in the joint frame
    bool prismatic = false;
    /// 0, 1 or 2 when `axis` is +-x, y or z of the joint frame (every DH-derived joint), with
    /// the sign in axis_sign: the rotation then changes two columns of the pose. -1 otherwise.
    int unit_axis = -1;
    double axis_sign = 1.0;
  };
  std::string base_link_;
  std::string tip_link_;
  int num_model_q_ = 0;
  std::vector<int> q_indices_;
  std::vector<std::string> joint_names_;
  std::vector<Segment> segments_;
  Eigen::Isometry3d X_LT_ = Eigen::Isometry3d::Identity();  // tip in the last joint's moving frame
  Eigen::VectorXd lower_;
  Eigen::VectorXd upper_;
};

/// Joints of the iCub 10-DOF right-arm chain in iKin order (torso pitch, roll, yaw, then the
/// seven right-arm joints), which MakeRightArmChain requires on the path.
std::vector<std::string> RightArmJointNames();

/// The 10-DOF chain torso + right arm from the model's root link to `tip_link` (default: the
/// palm frame "r_hand_dh_frame"). Throws std::invalid_argument naming the missing link or
/// joints when the model does not have exactly RightArmJointNames() as movable joints on the
/// path, in that order.
KinematicChain MakeRightArmChain(const robot::RobotModel& model, std::string_view tip_link = "r_hand_dh_frame");

/// Orientation error as an axis-angle vector [rad] in the base frame: log(R_target * R^T),
/// the rotation that takes R to R_target. Its norm is the angle between them, in [0, pi].
Eigen::Vector3d OrientationError(const Eigen::Matrix3d& R_target, const Eigen::Matrix3d& R);

}  // namespace toolbench::control
