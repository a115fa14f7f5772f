#include "control/motion.h"

#include <algorithm>
#include <cmath>

#include "common/check.h"

namespace toolbench::control {

double MinJerk(double tau) {
  const double s = std::clamp(tau, 0.0, 1.0);
  return s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
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
  require(max_speed >= 0 && std::isfinite(max_speed), "max_speed", max_speed, ">= 0");
  require(min_duration > 0, "min_duration", min_duration, "> 0");
  require(cruise_blend >= 0 && cruise_blend <= 0.5, "cruise_blend", cruise_blend, "in [0, 0.5]");
}

double MotionOptions::TrajectoryTime(double span, double fixed) const {
  // Nowhere to go (IK solutions of one pose from nearby postures differ by ~1e-5 rad): only the
  // wait for arrival.
  if (!(span > kNegligibleSpanRad)) return 0.0;
  if (max_speed <= 0) return fixed;
  constexpr double kMinJerkPeak = 1.875;  // max of dMinJerk/dtau, at tau = 1/2
  const double peak = cruise_blend > 0 ? 1.0 / (1.0 - cruise_blend) : kMinJerkPeak;
  return std::min(fixed, std::max(min_duration, peak * span / max_speed));
}

double CruiseProfile(double tau, double blend) {
  if (!(blend <= 0.5)) ThrowInvalid("CruiseProfile: blend = ", blend, " (expected <= 0.5)");
  const double s = std::clamp(tau, 0.0, 1.0);
  if (blend <= 0) return MinJerk(s);
  const double v = 1.0 / (1.0 - blend);  // cruise speed; each ramp covers v * blend / 2
  // Distance covered by a ramp after x [time fraction], velocity v * smoothstep(x / blend).
  auto ramp = [&](double x) {
    const double y = x / blend;
    return v * blend * (y * y * y - 0.5 * y * y * y * y);
  };
  if (s <= blend) return ramp(s);
  if (s >= 1.0 - blend) return 1.0 - ramp(1.0 - s);
  return v * blend / 2 + v * (s - blend);
}

namespace {

// Which joints a motion moves (the others' arrival is not awaited).
using JointMask = Eigen::Array<bool, Eigen::Dynamic, 1>;

// The full target vector for `goal` applied over `base` (the joints `goal` does not name keep
// their value in `base`); marks the named joints in `moved`.
Eigen::VectorXd Targets(const std::vector<std::string>& names, Eigen::VectorXd base,
                        const std::map<std::string, double>& goal, const char* function,
                        JointMask& moved) {
  for (const auto& [name, value] : goal) {
    auto it = std::find(names.begin(), names.end(), name);
    if (it == names.end()) ThrowInvalid(function, ": unknown joint '", name, "'");
    if (!std::isfinite(value)) ThrowInvalid(function, ": goal for '", name, "' is ", value);
    base[it - names.begin()] = value;
    moved[it - names.begin()] = true;
  }
  return base;
}

// Waits until every moved joint is within position_tol of its commanded target and slower than
// velocity_tol, or the timeout passes; t0 is when the motion began.
MotionResult AwaitArrival(RobotInterface& robot, const std::vector<std::string>& names,
                          const JointMask& moved, const MotionOptions& options,
                          double t0) {
  MotionResult result;
  const Eigen::ArrayXd mask = moved.cast<double>();
  const Eigen::VectorXd commanded = robot.PositionTargets();  // after the servo's clamping
  const double deadline = robot.Time() + options.timeout;
  while (true) {
    const Eigen::ArrayXd error = (robot.ReadEncoders() - commanded).array().abs() * mask;
    const double speed = (robot.ReadVelocities().array().abs() * mask).maxCoeff();
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

}  // namespace

MotionResult MoveJoints(RobotInterface& robot, const std::map<std::string, double>& goal,
                        const MotionOptions& options, const std::function<void()>& each_period) {
  options.Validate();
  const std::vector<std::string> names = robot.JointNames();
  const Eigen::VectorXd start = robot.PositionTargets();
  JointMask moved = JointMask::Constant(start.size(), false);
  const Eigen::VectorXd target = Targets(names, start, goal, "MoveJoints", moved);
  const double t0 = robot.Time();
  const double duration = options.TrajectoryTime((target - start).cwiseAbs().maxCoeff(), options.duration);
  for (double t = options.command_period; t < duration + 1e-9; t += options.command_period) {
    robot.SetPositionTargets(start + (target - start) * CruiseProfile(t / duration, options.cruise_blend));
    robot.Wait(options.command_period);
    if (each_period) each_period();
  }
  robot.SetPositionTargets(target);
  return AwaitArrival(robot, names, moved, options, t0);
}

MotionResult MoveThrough(RobotInterface& robot, const std::vector<std::map<std::string, double>>& goals,
                         const MotionOptions& options) {
  options.Validate();
  const std::vector<std::string> names = robot.JointNames();
  const double t0 = robot.Time();
  if (goals.empty()) {
    MotionResult result;
    result.reached = true;
    return result;
  }
  // The polyline's vertices and the cumulative length at each.
  std::vector<Eigen::VectorXd> vertices{robot.PositionTargets()};
  std::vector<double> at{0.0};
  JointMask moved = JointMask::Constant(vertices[0].size(), false);
  for (const auto& goal : goals) {
    vertices.push_back(Targets(names, vertices.back(), goal, "MoveThrough", moved));
    at.push_back(at.back() + (vertices.back() - vertices[vertices.size() - 2]).cwiseAbs().maxCoeff());
  }
  const double length = at.back();
  const double duration = options.TrajectoryTime(length, options.duration * static_cast<double>(goals.size()));
  size_t segment = 1;
  for (double t = options.command_period; t < duration + 1e-9; t += options.command_period) {
    const double s = length * CruiseProfile(t / duration, options.cruise_blend);
    while (segment + 1 < vertices.size() && at[segment] < s) ++segment;
    const double span = at[segment] - at[segment - 1];
    const double f = span > 0 ? std::clamp((s - at[segment - 1]) / span, 0.0, 1.0) : 1.0;
    robot.SetPositionTargets(vertices[segment - 1] + f * (vertices[segment] - vertices[segment - 1]));
    robot.Wait(options.command_period);
  }
  robot.SetPositionTargets(vertices.back());
  return AwaitArrival(robot, names, moved, options, t0);
}

}  // namespace toolbench::control
