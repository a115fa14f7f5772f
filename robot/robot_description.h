#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "robot/robot_model.h"

namespace toolbench::robot {

/// The helmet RGB-D camera's image geometry (square pixels, pinhole).
struct CameraSpec {
  double fovy_deg = 58.0;  // vertical field of view [deg], in (0, 180)
  int width = 640;         // [px], > 0
  int height = 480;        // [px], > 0
};

/// How the simulator drives one joint: a position servo with gain kp plus rotor inertia.
struct ActuatorSpec {
  double kp = 0.0;        // position gain [N m/rad], > 0
  double armature = 0.0;  // reflected rotor inertia [kg m^2], >= 0
};

/// Where the hand holds a handle: a cylinder of the given size whose axis passes through `center`
/// along `axis`, both in the palm frame P (thesis section 4.4.4: 32 mm x 80 mm).
struct GraspSpec {
  Eigen::Vector3d center{0.0, 0.0, 0.03};  // p_PH, handle axis centre in P [m]
  Eigen::Vector3d axis{0.0, 1.0, 0.0};     // unit handle axis in P
  double radius = 0.016;                   // [m]
  double length = 0.08;                    // [m]
};

/// Everything the bench knows about a robot: the URDF (the one source of kinematic truth) and a
/// JSON sidecar with what URDF cannot say (servo gains, hand groups, named postures, frames).
struct RobotDescription {
  std::filesystem::path sidecar_path;   // the JSON file read
  std::filesystem::path urdf_path;      // absolute path of the URDF it names
  RobotModel model;                     // parsed by urdfdom
  std::string root_link;                // robot root frame R
  std::string palm_frame;               // palm end-effector frame P (iKin convention)
  std::string camera_frame;             // helmet camera, OpenCV optical frame C
  CameraSpec camera;
  std::map<std::string, ActuatorSpec> actuators;               // by joint name, every movable joint
  std::map<std::string, std::vector<std::string>> hand_groups;  // group -> joints closing the hand
  GraspSpec grasp;                            // the hand's grasp cylinder
  std::map<std::string, double> hand_open;    // joint -> [rad]
  std::map<std::string, double> hand_preshape;  // joint -> [rad], before closing (thumb opposed)
  std::map<std::string, double> hand_closed;  // joint -> [rad]
  std::map<std::string, double> home;         // joint -> [rad] (sidecar stores degrees)

  /// Joint vector (model q order) of the home posture with the hand open; joints not named
  /// there are 0 clamped into their limits.
  Eigen::VectorXd HomeQ() const;

  /// Joint vector with named entries overwritten: base, then `values` (joint -> rad).
  /// Throws std::invalid_argument naming an unknown joint.
  Eigen::VectorXd WithJoints(const Eigen::VectorXd& base,
                             const std::map<std::string, double>& values) const;
};

/// Loads the sidecar JSON and the URDF it names (relative to the sidecar).
/// Throws std::invalid_argument naming the file and the field on any problem: unreadable file,
/// malformed JSON, missing field, joint or frame absent from the URDF, movable joint without an
/// actuator entry, non-positive gain.
RobotDescription LoadRobotDescription(const std::filesystem::path& sidecar_json);

/// The default robot: assets/robots/icub_upper_body.json.
std::filesystem::path DefaultRobotSidecar();

}  // namespace toolbench::robot
