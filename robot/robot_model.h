#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

namespace toolbench::robot {

/// A primitive or mesh shape attached to a link, in the link frame.
struct Geometry {
  enum class Type { kBox, kCylinder, kSphere, kMesh };
  Type type = Type::kBox;
  /// kBox: full extents (x, y, z) [m]; kCylinder: (radius, length, 0) [m], axis = geometry z;
  /// kSphere: (radius, 0, 0) [m]; kMesh: scale factors.
  Eigen::Vector3d size = Eigen::Vector3d::Zero();
  std::string mesh_file;                                    // kMesh only, as written in the URDF
  Eigen::Isometry3d X_LG = Eigen::Isometry3d::Identity();   // geometry G in link L
  Eigen::Vector4d rgba{0.8, 0.8, 0.8, 1.0};                 // colour from the URDF material
};

/// Mass properties of a link.
struct Inertial {
  double mass = 0.0;                                        // [kg], >= 0
  Eigen::Isometry3d X_LI = Eigen::Isometry3d::Identity();   // inertia frame I in link L
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();        // about the COM, in frame I [kg m^2]
};

/// A rigid link. Its frame is the frame of the joint that ends in it (URDF convention).
struct Link {
  std::string name;
  int parent_joint = -1;             // index into RobotModel::joints, -1 for the root link
  std::vector<int> child_joints;     // indices into RobotModel::joints
  Inertial inertial;
  std::vector<Geometry> visuals;
  std::vector<Geometry> collisions;
};

/// A joint between two links, URDF semantics: the child link frame is
/// X_PJ * (rotation about `axis` by q, or translation along it).
struct Joint {
  enum class Type { kRevolute, kContinuous, kPrismatic, kFixed };
  std::string name;
  Type type = Type::kFixed;
  int parent_link = -1;                                      // index into RobotModel::links
  int child_link = -1;                                       // index into RobotModel::links
  Eigen::Isometry3d X_PJ = Eigen::Isometry3d::Identity();   // joint frame in the parent link frame
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();           // unit, in the joint frame
  double lower = 0.0;      // position limit [rad or m]
  double upper = 0.0;      // position limit [rad or m]
  double effort = 0.0;     // force/torque limit [N or N m], 0 = unlimited
  double velocity = 0.0;   // speed limit [rad/s or m/s], 0 = unlimited
  double damping = 0.0;    // viscous damping [N m s/rad]
  double friction = 0.0;   // dry friction [N m]
  int q_index = -1;        // index in the joint-position vector, -1 for fixed joints
  bool movable() const { return type != Type::kFixed; }
};

/// A kinematic tree parsed from a URDF by urdfdom. Links are stored parent before child
/// (depth-first from the root), so one pass over `links` computes forward kinematics.
struct RobotModel {
  std::string name;
  std::vector<Link> links;
  std::vector<Joint> joints;
  std::vector<int> movable_joints;   // joint indices in q order (q_index = position in this list)

  /// Index of a link; throws std::invalid_argument naming the link and the model if unknown.
  int LinkIndex(std::string_view link_name) const;
  /// Index of a joint; throws std::invalid_argument naming the joint if unknown.
  int JointIndex(std::string_view joint_name) const;
  /// Number of movable joints (size of q).
  int num_q() const { return static_cast<int>(movable_joints.size()); }
  /// Names of the movable joints in q order.
  std::vector<std::string> JointNames() const;
};

/// Parses URDF text with urdfdom. `source` names the input in error messages.
/// Throws std::invalid_argument when urdfdom rejects the text or a joint type is unsupported
/// (floating, planar).
RobotModel ParseUrdf(const std::string& urdf_xml, std::string_view source);

/// Reads and parses a URDF file; throws std::invalid_argument naming the path on failure.
RobotModel LoadUrdf(const std::filesystem::path& urdf_path);

/// Poses of every link in the root-link frame R (X_RL, indexed like model.links) for joint
/// positions q (model.num_q() entries, [rad] / [m]). Throws std::invalid_argument on a wrong
/// size or a non-finite entry.
std::vector<Eigen::Isometry3d> LinkPoses(const RobotModel& model, const Eigen::VectorXd& q);

/// Pose of one link in the root frame; see LinkPoses.
Eigen::Isometry3d LinkPose(const RobotModel& model, const Eigen::VectorXd& q,
                           std::string_view link_name);

}  // namespace toolbench::robot
