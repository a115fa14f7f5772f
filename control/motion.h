#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/robot_interface.h"

namespace toolbench::control {

/// Minimum-jerk time scaling s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 for tau in [0, 1] (clamped):
/// zero velocity and acceleration at both ends.
double MinJerk(double tau);

/// Time scaling s(tau) in [0, 1] for tau in [0, 1] (clamped) that cruises at constant speed
/// 1 / (1 - blend) between a smooth (smoothstep-velocity) start and stop, each taking the fraction
/// blend of the time; blend in (0, 0.5]; blend <= 0 gives MinJerk. Zero velocity at both ends and
/// a peak speed 1 / (1 - blend) times the mean (minimum jerk: 1.875). Throws
/// std::invalid_argument for blend > 0.5 or NaN.
double CruiseProfile(double tau, double blend);

/// A motion whose largest joint change is at most this [rad] has no trajectory
/// (MotionOptions::TrajectoryTime).
inline constexpr double kNegligibleSpanRad = 1e-3;

/// How a joint motion is executed and judged done.
struct MotionOptions {
  double duration = 1.5;        // trajectory time [s], > 0 (with max_speed: the longest)
  double command_period = 0.01; // period of target updates [s], > 0
  double position_tol = 0.02;   // |q - q_target| per joint to count as arrived [rad], > 0
  double velocity_tol = 0.05;   // |qdot| per joint to count as still [rad/s], > 0
  double timeout = 2.0;         // extra time allowed after the trajectory ends [s], >= 0
  /// Peak joint speed [rad/s], >= 0. When > 0 a motion lasts just long enough to keep its
  /// fastest joint at or below it (a minimum-jerk profile peaks at 1.875 x its mean speed), but
  /// at least min_duration and at most duration: a short move no longer takes as long as a long
  /// one. 0: every motion lasts duration.
  double max_speed = 0.0;
  double min_duration = 0.3;    // [s], > 0; used with max_speed
  /// Time scaling: 0 = minimum jerk; in (0, 0.5]: CruiseProfile with this blend (constant speed
  /// between short start and stop ramps, for pushing something along at an even pace).
  double cruise_blend = 0.0;
  /// The trajectory time [s] of a motion whose largest joint change (MoveThrough: joint-space
  /// path length, segments by their largest joint change) is `span` [rad], >= 0, and whose fixed
  /// time would be `fixed` [s]. 0 for a span up to kNegligibleSpanRad: a motion to where the
  /// targets already are only waits for the encoders' arrival (such no-op moves, e.g. a straight
  /// line down from a pose that is already high enough, took their full fixed time: 1.5 s of an
  /// episode's ~42 s of robot time).
  double TrajectoryTime(double span, double fixed) const;
  void Validate() const;        // throws std::invalid_argument naming the field
};

/// Peak joint speed [rad/s] of the free motions between tasks (joint-space transfers, the looks
/// at the table and the rack): 86 deg/s, about what the longest of those transfers (1.5 rad in
/// a fixed 2 s) already reached, so that the short ones stop taking as long as the long ones.
inline constexpr double kTransferSpeed = 1.5;

/// Outcome of a joint motion (an expected failure is a result, not an exception).
struct MotionResult {
  bool reached = false;        // the moved joints within position_tol and still before the timeout
  double max_error = 0.0;      // largest |q - q_target| of the moved joints at the end [rad]
  std::string worst_joint;     // joint with max_error
  double elapsed = 0.0;        // robot time spent [s]
};

/// Moves the named joints (others keep their targets) along a minimum-jerk path to `goal`
/// [rad] by streaming position targets, then waits until the encoders say the motion of those
/// joints is done or the timeout passes (a finger squeezing a tool never reaches its target and
/// must not hold up a gaze or arm motion). `each_period`, when set, is called after every
/// command period of the trajectory (not of the wait for arrival): e.g. a person holding an
/// object still while the fingers close on it. Throws std::invalid_argument naming an unknown
/// joint or a non-finite goal.
MotionResult MoveJoints(RobotInterface& robot, const std::map<std::string, double>& goal,
                        const MotionOptions& options = {}, const std::function<void()>& each_period = {});

/// Moves through a sequence of goals (each as MoveJoints takes it: named joints, the others keep
/// their targets) without stopping at the intermediate ones: the targets run along the
/// joint-space polyline start -> goals[0] -> ... -> goals.back() with one minimum-jerk time law
/// over its whole length (segments by their largest joint change), lasting `options.duration`
/// per goal (with max_speed: at most, see MotionOptions::TrajectoryTime); then waits for arrival at the last goal as MoveJoints does. Stopping at every IK
/// waypoint of a straight Cartesian line and waiting for the encoders there took longer for the
/// same peak speed (a grasp's approach through 8 waypoints: 5.5 s of robot time instead of 4.0 s).
/// An empty sequence does nothing (reached, elapsed 0). Throws std::invalid_argument as
/// MoveJoints does.
MotionResult MoveThrough(RobotInterface& robot, const std::vector<std::map<std::string, double>>& goals,
                         const MotionOptions& options = {});

}  // namespace toolbench::control
