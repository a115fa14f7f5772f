#include "control/motion.h"

#include <algorithm>
#include <cmath>

#include "common/check.h"

namespace toolbench::control {

double MinJerk(double tau) {
  const double s = std::clamp(tau, 0.0, 1.0);
  return s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
}

Eigen::VectorXd MinJerkPoint(const Eigen::VectorXd& q0, const Eigen::VectorXd& q1, double t,
                             double T) {
  if (q0.size() != q1.size()) ThrowInvalid("MinJerkPoint: sizes ", q0.size(), " and ", q1.size());
  if (!(T > 0)) ThrowInvalid("MinJerkPoint: duration ", T, " must be > 0");
  return q0 + (q1 - q0) * MinJerk(t / T);
}

void MotionOptions::Validate() const {
  auto require = [](bool ok, const char* field, double value, const char* expected) {
    if (!ok) ThrowInvalid("MotionOptions: ", field, " = ", value, ", expected ", expected);
  };
  require(duration > 0, "duration", duration, "> 0");
  require(command_period > 0, "command_period", command_period, "> 0");
  require(position_tol > 0, "position_tol", position_tol, "> 0");
  require(velocity_tol > 0, "velocity_tol", velocity_tol, "> 0");
  require(timeout >= 0, "timeout", timeout, ">= 0");
}

MotionResult MoveJoints(RobotInterface& robot, const std::map<std::string, double>& goal,
                        const MotionOptions& options) {
  options.Validate();
  const std::vector<std::string> names = robot.JointNames();
  const Eigen::VectorXd start = robot.PositionTargets();
  Eigen::VectorXd target = start;
  for (const auto& [name, value] : goal) {
    auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) ThrowInvalid("MoveJoints: unknown joint '", name, "'");
    if (!std::isfinite(value)) ThrowInvalid("MoveJoints: goal for '", name, "' is ", value);
    target[it - names.begin()] = value;
  }
  const double t0 = robot.Time();
  for (double t = options.command_period; t < options.duration + 1e-9;
       t += options.command_period) {
    robot.SetPositionTargets(MinJerkPoint(start, target, t, options.duration));
    robot.Wait(options.command_period);
  }
  robot.SetPositionTargets(target);

  MotionResult result;
  const Eigen::VectorXd commanded = robot.PositionTargets();  // after the servo's clamping
  const double deadline = robot.Time() + options.timeout;
  while (true) {
    const Eigen::VectorXd error = (robot.ReadEncoders() - commanded).cwiseAbs();
    const double speed = robot.ReadVelocities().cwiseAbs().maxCoeff();
    Eigen::Index worst = 0;
    result.max_error = error.maxCoeff(&worst);
    result.worst_joint = names[worst];
    if (result.max_error < options.position_tol && speed < options.velocity_tol) {
      result.reached = true;
      break;
    }
    if (robot.Time() >= deadline) break;
    robot.Wait(options.command_period);
  }
  result.elapsed = robot.Time() - t0;
  return result;
}

}  // namespace toolbench::control
