#pragma once

#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "common/robot_interface.h"

struct mjModel_;
struct mjData_;

namespace toolbench::sim {

/// Simulator state that only scoring and tests may read (design.md: perception and control never
/// see it). Poses of every named body in the world frame W at one instant.
struct GroundTruth {
  double time = 0.0;                                  // [s]
  std::map<std::string, Eigen::Isometry3d> X_WB;      // body name -> pose in W
  /// Pose of a body; throws std::invalid_argument naming an unknown body.
  const Eigen::Isometry3d& Pose(std::string_view body) const;
};

/// Health of the simulation after stepping, from MuJoCo's warning counters.
struct SimStatus {
  bool ok = true;            // false once MuJoCo reported instability (NaN/Inf, bad QACC) or ran
                             // out of room for contacts or constraint rows (PhysicsSpec)
  std::string message;       // the first warning, empty when ok
};

/// What stepping the physics has cost so far (for the stage timings of episodes and benches).
struct PhysicsStats {
  long steps = 0;             // mj_step calls
  double wall_s = 0.0;        // wall time inside mj_step [s]
  long contacts = 0;          // sum over steps of the active contacts
  long constraint_rows = 0;   // sum over steps of the constraint rows (nefc)
  long asleep = 0;            // sum over steps of the free bodies asleep (see SleepSettings)
  /// Sum over steps of the constraint solver's iterations (mjData::solver_iter: in MuJoCo 2.2.2
  /// the noslip pass's iterations, when a scene has one, are counted in it).
  long solver_iterations = 0;
  /// Steps that ran the noslip pass (all of them with PhysicsSpec::noslip_scope "always").
  long noslip_steps = 0;
  /// The difference of two readings (what happened between them).
  PhysicsStats operator-(const PhysicsStats& before) const {
    return {steps - before.steps,
            wall_s - before.wall_s,
            contacts - before.contacts,
            constraint_rows - before.constraint_rows,
            asleep - before.asleep,
            solver_iterations - before.solver_iterations,
            noslip_steps - before.noslip_steps};
  }
};

/// Sleeping of free bodies at rest, as game and robotics engines do (MuJoCo 2.2.2 has none): a
/// tool or ball that has moved less than tolerance_m (rotations at a 0.1 m lever) for window_s,
/// with no robot collision geom and no awake free body within wake_margin_m of its collision
/// geoms, leaves the contact solve (its geoms stop colliding) and is held exactly where it rests;
/// it wakes, with its collisions back, once a robot geom or an awake free body comes within
/// wake_margin_m (of a box enclosing each geom, oriented with it; the bounding sphere for planes
/// and height fields), when it is teleported, or on a reset. Bodies near each other
/// fall asleep together or not at all. Resting tools make most of a step's contact rows and the
/// noslip pass costs about their square: with 30 noslip iterations a scene at rest stepped ~5x
/// faster asleep, one with a tool in the hand ~1.7x. Off (window_s = 0) it is MuJoCo's plain
/// physics. The composer writes it into the MJCF as
/// <numeric name="toolbench_sleep" data="window tolerance margin"/>.
struct SleepSettings {
  double window_s = 0.0;        // [s], >= 0; 0 = never sleep
  double tolerance_m = 2.5e-4;  // [m], > 0
  double wake_margin_m = 0.02;  // [m], > 0: more than a body moves in a step
};

/// A MuJoCo model and its data: loads MJCF, steps physics, reads encoders and drives the position
/// servos. Not copyable; movable. Not thread-safe (one World per thread). When the model has
/// <text name="toolbench_noslip_fixtures" data="prefix"/> (the composer writes "rack_" for
/// PhysicsSpec::noslip_scope "resting"), the model's noslip pass runs only in the steps after one
/// in which a free body touched a geom whose name has that prefix and no robot geom
/// (PhysicsStats::noslip_steps counts the steps that ran it).
class World {
 public:
  /// Compiles MJCF text (asset paths must be absolute). `source` names the input in errors.
  /// Throws std::invalid_argument with MuJoCo's message when the model does not compile.
  World(const std::string& mjcf, std::string_view source);
  ~World();
  World(World&&) noexcept;
  World& operator=(World&&) noexcept;
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  /// Resets to the named keyframe (the composer writes "home"). Throws on an unknown key.
  void ResetToKeyframe(std::string_view key = "home");
  /// Advances physics by `steps` steps. Returns the status (unstable physics is reported, never
  /// thrown, so a benchmark can record it and go on).
  SimStatus Step(int steps = 1);
  /// Advances physics by at least `seconds` of simulated time.
  SimStatus Advance(double seconds);
  /// Steps until every free body (tools, ball) moved less than speed_tol * hold over a window of
  /// `hold` seconds (rotations count at a 0.1 m lever), or `max_time` has passed. Returns true
  /// when everything came to rest; physics failures show in status().
  bool SettleFreeBodies(double max_time, double speed_tol = 1e-3, double hold = 0.25);
  double time() const;      // simulated time [s]
  double timestep() const;  // [s]
  SimStatus status() const;
  /// Steps taken and their cost since construction (never reset).
  const PhysicsStats& physics_stats() const;
  /// The sleeping settings read from the model (window_s 0 when it has none).
  const SleepSettings& sleep_settings() const;
  /// Whether the named free body is asleep; throws std::invalid_argument naming an unknown body
  /// or one without a free joint.
  bool IsAsleep(std::string_view body) const;

  /// Actuated joints (one position servo each), in actuator order.
  const std::vector<std::string>& actuated_joints() const;
  Eigen::VectorXd JointPositions() const;   // encoders [rad], actuated_joints() order
  Eigen::VectorXd JointVelocities() const;  // [rad/s]
  Eigen::VectorXd JointTargets() const;     // current servo targets [rad]
  /// Sets servo targets; throws std::invalid_argument on a wrong size or non-finite entry.
  void SetJointTargets(const Eigen::VectorXd& q_target);
  /// Sets joint positions and targets directly and zeroes their velocities (for setting up a
  /// test or a posture at time 0; not for use during an episode).
  void TeleportJoints(const Eigen::VectorXd& q);

  /// Moves a body with a free joint (a tool, the ball) to X_WB at rest. The one use permitted
  /// during an episode is the recorded hand-over fallback (a human puts the tool in the hand);
  /// callers must record it. Throws std::invalid_argument naming an unknown body, one without a
  /// free joint, or a non-finite pose.
  void TeleportFreeBody(std::string_view body, const Eigen::Isometry3d& X_WB);

  /// Snapshot of all named body poses (ground truth, for scoring and tests only).
  GroundTruth ground_truth() const;
  /// Number of active contacts.
  int num_contacts() const;
  /// Names of the bodies currently in contact with `body` (ground truth, for scoring/tests).
  std::vector<std::string> ContactingBodies(std::string_view body) const;

  /// MuJoCo handles for the renderer and benchmarks inside sim/ (opaque elsewhere).
  const mjModel_* mj_model() const;
  mjData_* mj_data();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The simulated robot behind the RobotInterface that control uses.
class SimRobot : public RobotInterface {
 public:
  /// Keeps a reference; `world` must outlive this object.
  explicit SimRobot(World& world) : world_(world) {}
  std::vector<std::string> JointNames() const override { return world_.actuated_joints(); }
  Eigen::VectorXd ReadEncoders() const override { return world_.JointPositions(); }
  Eigen::VectorXd ReadVelocities() const override { return world_.JointVelocities(); }
  void SetPositionTargets(const Eigen::VectorXd& q) override { world_.SetJointTargets(q); }
  Eigen::VectorXd PositionTargets() const override { return world_.JointTargets(); }
  /// Advances the physics. Throws std::runtime_error (naming MuJoCo's warning and the time) once
  /// the simulation is unstable: its time no longer advances, so a motion waiting for it would
  /// wait forever. The episode records the exception as the stage's failure; benches record it
  /// as the case's.
  void Wait(double seconds) override {
    world_.Advance(seconds);
    if (!world_.status().ok) throw std::runtime_error("simulation unstable: " + world_.status().message);
  }
  double Time() const override { return world_.time(); }

 private:
  World& world_;
};

/// Installs MuJoCo error/warning handlers that log through spdlog instead of MuJoCo 2.2.2's
/// default (print "Press Enter", read stdin, exit). Idempotent; World's constructor calls it.
void InstallMujocoHandlers();

}  // namespace toolbench::sim
