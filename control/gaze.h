#pragma once

#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "robot/robot_description.h"

namespace toolbench::control {

/// Which joints gaze may use and how much each is discouraged from moving.
struct GazeOptions {
  /// Joint -> weight on moving away from the current posture [1/rad^2], >= 0. The torso is
  /// weighted more so the neck does the work and the torso helps only when the neck cannot.
  std::map<std::string, double> joint_weights{{"neck_pitch", 0.01}, {"neck_yaw", 0.01},
                                              {"neck_roll", 0.01}, {"torso_yaw", 0.05},
                                              {"torso_pitch", 0.5}};
  double level_weight = 0.3;   // weight of keeping the image horizon level (x_C horizontal), >= 0
  double tolerance_deg = 1.0;  // accepted angle between optical axis and target [deg], > 0
  int max_iterations = 100;    // damped Gauss-Newton iterations, > 0
  void Validate() const;       // throws std::invalid_argument naming the field
};

/// Result of a gaze solve (expected failure is a result, not an exception).
struct GazeResult {
  bool converged = false;       // optical axis within tolerance of the target
  double error_deg = 0.0;       // final angle between optical axis and target direction [deg]
  Eigen::VectorXd q;            // full joint vector (model q order) to command
  std::map<std::string, double> joints;  // the gaze joints' solution [rad]
};

/// Points the camera frame's optical axis (+z) at `p_R_target` (robot root frame [m]), with the
/// image horizon kept level as far as the neck roll allows, by moving
/// the joints in options.joint_weights from `q_current`, within their limits. Damped
/// Gauss-Newton on forward kinematics of the URDF; when that stops short of the tolerance, again
/// from those joints at zero, and the closer of the two. Throws std::invalid_argument for a
/// non-finite target, a wrong-size q or an unknown joint.
GazeResult LookAt(const robot::RobotDescription& robot, const Eigen::VectorXd& q_current,
                  const Eigen::Vector3d& p_R_target, const GazeOptions& options = {});

}  // namespace toolbench::control
