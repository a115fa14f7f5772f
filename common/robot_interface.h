#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace toolbench {

/// What a controller may do with a robot, as iCub software does through YARP device interfaces:
/// read joint encoders, send joint position targets, and let time pass. The simulator implements
/// it; a driver for the real robot could. Joint order is JointNames() order throughout.
class RobotInterface {
 public:
  virtual ~RobotInterface() = default;
  /// Names of the controllable joints, in the order of every vector below.
  virtual std::vector<std::string> JointNames() const = 0;
  /// Measured joint positions [rad].
  virtual Eigen::VectorXd ReadEncoders() const = 0;
  /// Measured joint velocities [rad/s].
  virtual Eigen::VectorXd ReadVelocities() const = 0;
  /// Position targets for the joint servos [rad]; clamped to the joint limits by the servo.
  /// Throws std::invalid_argument on a wrong size or a non-finite entry.
  virtual void SetPositionTargets(const Eigen::VectorXd& q_target) = 0;
  /// Current position targets [rad].
  virtual Eigen::VectorXd PositionTargets() const = 0;
  /// Lets `seconds` of robot time pass (the simulator steps; a real robot would sleep).
  virtual void Wait(double seconds) = 0;
  /// Robot clock [s].
  virtual double Time() const = 0;
};

}  // namespace toolbench
