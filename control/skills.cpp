#include "control/skills.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "common/check.h"
#include "control/kinematics.h"

namespace toolbench::control {
namespace {

// How much nearer than where the pull's transfer starts a tool may come to a fixture it is already
// within PullOptions::fixture_clearance_m of [m] (the hand holds still, the tool sags a little).
constexpr double kFixtureSlackM = 0.002;

// Model q (URDF order) from values named by the robot interface; joints it does not cover keep
// their home value.
Eigen::VectorXd ModelQFrom(const robot::RobotDescription& desc, const std::vector<std::string>& names,
                           const Eigen::VectorXd& values) {
  Eigen::VectorXd q = desc.HomeQ();
  for (size_t i = 0; i < names.size(); ++i) {
    const int j = desc.model.JointIndex(names[i]);
    const int qi = desc.model.joints[j].q_index;
    if (qi >= 0) q[qi] = values[static_cast<Eigen::Index>(i)];
  }
  return q;
}

std::map<std::string, double> ChainGoal(const KinematicChain& chain, const Eigen::VectorXd& q_model) {
  std::map<std::string, double> goal;
  for (int i = 0; i < chain.num_joints(); ++i) goal[chain.joint_names()[i]] = q_model[chain.q_indices()[i]];
  return goal;
}

// The chain's joints at q_model and the hand open: a move of the arm with an open hand.
std::map<std::string, double> OpenHandGoal(const KinematicChain& chain, const Eigen::VectorXd& q_model,
                                           const robot::RobotDescription& desc) {
  std::map<std::string, double> goal = ChainGoal(chain, q_model);
  for (const auto& [joint, value] : desc.hand_open) goal[joint] = value;
  return goal;
}

// Position servos sag under gravity and load (steady-state error = torque / kp). Adds the
// measured error of the chain joints to their targets, a few times, so that the encoders (and
// hence the hand) end where IK put them. Uses encoders only, as a real robot could. Returns the
// offsets it left on the targets (model q, zero off the chain), to carry into nearby postures.
Eigen::VectorXd CompensateSag(RobotInterface& robot, const std::vector<std::string>& names, const KinematicChain& chain,
                              const Eigen::VectorXd& q_model_goal, const SagCompensation& sag) {
  std::vector<Eigen::Index> index(chain.num_joints());
  for (int i = 0; i < chain.num_joints(); ++i) {
    index[i] = std::find(names.begin(), names.end(), chain.joint_names()[i]) - names.begin();
  }
  Eigen::VectorXd offsets = Eigen::VectorXd::Zero(q_model_goal.size());
  for (int k = 0; k < sag.iterations; ++k) {
    const Eigen::VectorXd enc = robot.ReadEncoders();
    Eigen::VectorXd target = robot.PositionTargets();
    for (int i = 0; i < chain.num_joints(); ++i) {
      const double goal = q_model_goal[chain.q_indices()[i]];
      const double offset = std::clamp(target[index[i]] - goal + (goal - enc[index[i]]), -sag.max_offset_rad,
                                       sag.max_offset_rad);
      target[index[i]] = goal + offset;
      offsets[chain.q_indices()[i]] = offset;
    }
    robot.SetPositionTargets(target);
    robot.Wait(sag.wait_s);
  }
  return offsets;
}

Eigen::Matrix3d RotZ(double angle) { return Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix(); }

struct Plan {
  Eigen::Isometry3d X_RP = Eigen::Isometry3d::Identity();
  double roll = 0.0;
  bool flipped = false;
  double slide = 0.0;
  double rest_cost = 0.0;
  Eigen::VectorXd q_grasp;
  Eigen::VectorXd q_pregrasp;             // end of the joint-space transfer: staging pose, else pre-grasp
  std::vector<Eigen::VectorXd> transfer_via;  // joint-space via postures before q_pregrasp
  const char* transfer_route = "direct";      // how: ClearTransfer's route names
  std::vector<Eigen::VectorXd> approach;  // staging (exclusive) -> pre-grasp -> grasp (inclusive)
  std::vector<Eigen::VectorXd> lift;
};

bool Converged(const IkResult& r) { return r.status == IkStatus::kConverged; }

// Largest gap between a long finger joint's encoder and its hand_closed target [rad]: near zero
// when the fingers closed on nothing.
double FingerGap(const RobotInterface& robot, const robot::RobotDescription& desc) {
  const std::vector<std::string> names = robot.JointNames();
  const Eigen::VectorXd enc = robot.ReadEncoders();
  double max_gap = 0.0;
  for (const auto& [joint, value] : desc.hand_closed) {
    if (joint.rfind("r_thumb", 0) == 0) continue;
    const auto it = std::find(names.begin(), names.end(), joint);
    if (it == names.end()) continue;
    max_gap = std::max(max_gap, std::abs(enc[it - names.begin()] - value));
  }
  return max_gap;
}

// Largest |encoder - goal| over the chain joints [rad] (the hand joints squeezing a tool never
// "arrive", so MoveJoints' own verdict cannot be used while holding one); names the joint.
double ChainError(const RobotInterface& robot, const KinematicChain& chain, const Eigen::VectorXd& q_model_goal,
                  std::string* worst) {
  const std::vector<std::string> names = robot.JointNames();
  const Eigen::VectorXd enc = robot.ReadEncoders();
  double max_error = 0.0;
  for (int i = 0; i < chain.num_joints(); ++i) {
    const auto it = std::find(names.begin(), names.end(), chain.joint_names()[i]);
    if (it == names.end()) continue;
    const double e = std::abs(enc[it - names.begin()] - q_model_goal[chain.q_indices()[i]]);
    if (e > max_error) {
      max_error = e;
      *worst = chain.joint_names()[i];
    }
  }
  return max_error;
}

// `base` for a streamed path of n waypoints that share total_s [s] of motion, each at least
// min_each_s [s] (not speed-limited: the time is the path's).
MotionOptions SharedTime(MotionOptions base, double total_s, double min_each_s, size_t n) {
  base.max_speed = 0.0;
  base.duration = std::max(min_each_s, total_s / static_cast<double>(std::max<size_t>(1, n)));
  return base;
}

// Follows joint-space waypoints with the hand targets untouched, without stopping at each
// (MoveThrough: motion.duration per waypoint).
MotionResult FollowWaypoints(RobotInterface& robot, const KinematicChain& chain, const std::vector<Eigen::VectorXd>& path,
                             const MotionOptions& motion) {
  std::vector<std::map<std::string, double>> goals;
  goals.reserve(path.size());
  for (const Eigen::VectorXd& q : path) goals.push_back(ChainGoal(chain, q));
  return MoveThrough(robot, goals, motion);
}

}  // namespace

void SagCompensation::Validate() const {
  if (iterations < 0) ThrowInvalid("SagCompensation: iterations = ", iterations, ", expected >= 0");
  if (!(wait_s > 0)) ThrowInvalid("SagCompensation: wait_s = ", wait_s, ", expected > 0");
  if (!(max_offset_rad >= 0)) ThrowInvalid("SagCompensation: max_offset_rad = ", max_offset_rad, ", expected >= 0");
}

void HandleSlide::Validate(const std::string& field) const {
  auto fail = [&](const char* end, double value, const char* expected) {
    ThrowInvalid(field, " = [", min_m, ", ", max_m, "]: ", field, end, " = ", value, " (expected ", expected, ")");
  };
  if (!(min_m <= 0) || !std::isfinite(min_m)) fail(".min_m", min_m, "finite, <= 0");
  if (!(max_m >= 0) || !std::isfinite(max_m)) fail(".max_m", max_m, "finite, >= 0");
}

void GraspOptions::Validate() const {
  auto fail = [](const char* field, double value, const char* expected) {
    ThrowInvalid("GraspOptions: ", field, " = ", value, " (expected ", expected, ")");
  };
  handle_slide.Validate("GraspOptions: handle_slide");
  if (!(slide_step_m > 0)) fail("slide_step_m", slide_step_m, "> 0");
  if (!(roll_step_rad > 0 && roll_step_rad <= M_PI)) fail("roll_step_rad", roll_step_rad, "in (0, pi]");
  if (!(min_approach_cos >= -1 && min_approach_cos <= 1)) fail("min_approach_cos", min_approach_cos, "in [-1, 1]");
  if (!(max_approach_up_cos >= -1 && max_approach_up_cos <= 1)) {
    fail("max_approach_up_cos", max_approach_up_cos, "in [-1, 1]");
  }
  if (axis_direction < -1 || axis_direction > 1) fail("axis_direction", axis_direction, "-1, 0 or +1");
  if (!(pregrasp_back_m >= 0)) fail("pregrasp_back_m", pregrasp_back_m, ">= 0");
  if (!(pregrasp_up_m >= 0)) fail("pregrasp_up_m", pregrasp_up_m, ">= 0");
  if (!(staging_back_m >= 0)) fail("staging_back_m", staging_back_m, ">= 0");
  if (!(staging_up_m >= 0)) fail("staging_up_m", staging_up_m, ">= 0");
  if (!(obstacle_margin_m >= 0)) fail("obstacle_margin_m", obstacle_margin_m, ">= 0");
  if (max_regrasps < 0) fail("max_regrasps", max_regrasps, ">= 0");
  if (!(transfer_check_step_rad > 0)) fail("transfer_check_step_rad", transfer_check_step_rad, "> 0");
  if (!(transfer_inward_m >= 0)) fail("transfer_inward_m", transfer_inward_m, ">= 0");
  for (const double raise : transfer_raise_m) {
    if (!(raise > 0) || !std::isfinite(raise)) fail("transfer_raise_m", raise, "finite, > 0");
  }
  if (approach_waypoints < 1) fail("approach_waypoints", approach_waypoints, ">= 1");
  if (!(lift_m >= 0)) fail("lift_m", lift_m, ">= 0");
  if (lift_waypoints < 1) fail("lift_waypoints", lift_waypoints, ">= 1");
  if (!(lift_retreat_m >= 0)) fail("lift_retreat_m", lift_retreat_m, ">= 0");
  if (!(lift_max_m >= 0)) fail("lift_max_m", lift_max_m, ">= 0");
  if (!(lift_step_m > 0)) fail("lift_step_m", lift_step_m, "> 0");
  if (path_restarts < 0) fail("path_restarts", path_restarts, ">= 0");
  if (path_ipopt_iterations < 0) fail("path_ipopt_iterations", path_ipopt_iterations, ">= 0");
  if (!(fallback_max_error_m >= 0)) fail("fallback_max_error_m", fallback_max_error_m, ">= 0");
  if (!(touching_depth_step_m > 0)) fail("touching_depth_step_m", touching_depth_step_m, "> 0");
  if (!(preshape_time > 0)) fail("preshape_time", preshape_time, "> 0");
  if (!(close_time >= 0.5)) fail("close_time", close_time, ">= 0.5");
  if (!(settle_time >= 0)) fail("settle_time", settle_time, ">= 0");
  if (!(hold_time >= 0)) fail("hold_time", hold_time, ">= 0");
  if (!(empty_hand_tol > 0)) fail("empty_hand_tol", empty_hand_tol, "> 0");
  if (screening_restarts < 0) fail("screening_restarts", screening_restarts, ">= 0");
  if (screening_ipopt_iterations < 0) fail("screening_ipopt_iterations", screening_ipopt_iterations, ">= 0");
  if (fallback_restarts < 0) fail("fallback_restarts", fallback_restarts, ">= 0");
  if (fallback_ipopt_iterations < 0) fail("fallback_ipopt_iterations", fallback_ipopt_iterations, ">= 0");
  if (!(fallback_min_approach_cos >= -1 && fallback_min_approach_cos <= 1)) {
    fail("fallback_min_approach_cos", fallback_min_approach_cos, "in [-1, 1]");
  }
  if (!(retreat_m >= 0)) fail("retreat_m", retreat_m, ">= 0");
  sag.Validate();
  if (!(arm_arrival_tol > 0)) fail("arm_arrival_tol", arm_arrival_tol, "> 0");
  transfer.Validate();
  approach.Validate();
  lift.Validate();
  ik.Validate();
}

const char* ToString(GraspStatus status) {
  switch (status) {
    case GraspStatus::kGrasped: return "grasped";
    case GraspStatus::kUnreachable: return "unreachable";
    case GraspStatus::kIkFailed: return "ik_failed";
    case GraspStatus::kMotionTimeout: return "motion_timeout";
    case GraspStatus::kEmptyHand: return "empty_hand";
    case GraspStatus::kDropped: return "dropped";
    case GraspStatus::kRejected: return "rejected";
  }
  return "unknown";
}

bool PlanningFailed(GraspStatus status) {
  return status == GraspStatus::kUnreachable || status == GraspStatus::kIkFailed || status == GraspStatus::kRejected;
}

namespace {

// Where the open hand (`open`), or the preshaped one (`preshaped`: the thumb swung into
// opposition), comes closer than the margin to a fixture at the grasp posture q_model.
std::optional<ClearanceHit> HandHitAtGrasp(const ArmClearance& open, const ArmClearance& preshaped,
                                           const Eigen::VectorXd& q_model) {
  if (auto hit = open.Check(q_model)) return hit;
  return preshaped.Check(q_model);
}

// Where the open or the preshaped hand comes closest to a fixture at the grasp posture q_model
// (the nearer of the two; distance_m negative: that deep inside), or nothing without fixtures.
std::optional<ClearanceHit> HandClosestAtGrasp(const ArmClearance& open, const ArmClearance& preshaped,
                                               const Eigen::VectorXd& q_model) {
  std::optional<ClearanceHit> closest = open.Closest(q_model);
  if (auto other = preshaped.Closest(q_model); other && (!closest || other->distance_m < closest->distance_m)) {
    closest = other;
  }
  return closest;
}

// `base` with `restarts` pre-solve restarts and `ipopt_iterations` of Ipopt after a failed
// pre-solve (0: no Ipopt): a cheap screening of many candidate poses (most out of reach), a path
// waypoint warm-started from its neighbour, or a solve whose Ipopt rescue never pays.
IkOptions LimitedIk(const IkOptions& base, int restarts, int ipopt_iterations) {
  IkOptions o = base;
  o.presolve_restarts = restarts;
  o.max_iterations = std::max(1, ipopt_iterations);
  o.ipopt_after_failed_presolve = ipopt_iterations > 0;
  return o;
}

/// Checks a planned grasp path's joint-space transfer from q_now to plan->q_pregrasp against the
/// obstacles. A blocked transfer is tried again through via postures, for each of
/// options.transfer_raise_m in turn: the transfer's end raised (then down onto it), the current
/// palm raised (then across), and both; then joint by joint: the arm bent up first, or the torso
/// turned last; then through the home posture q_home (the arm's joints and the torso's), alone or
/// followed by each raised route as from home. The first clear one sets plan->transfer_via and
/// plan->transfer_route. False when the transfer stays blocked (counted and described in *result).
bool ClearTransfer(const ArmClearance& clearance, CartesianSolver& solver, const KinematicChain& chain,
                   const Eigen::VectorXd& q_now, const Eigen::VectorXd& q_home, const GraspOptions& options,
                   Plan* plan, GraspResult* result) {
  const double step = options.transfer_check_step_rad;
  auto first_hit = [&](const std::vector<Eigen::VectorXd>& via) {
    Eigen::VectorXd from = q_now;
    for (const Eigen::VectorXd& q : via) {
      if (auto hit = clearance.CheckLine(from, q, step)) return hit;
      from = q;
    }
    return clearance.CheckLine(from, plan->q_pregrasp, step);
  };
  const std::optional<ClearanceHit> hit = first_hit({});
  if (!hit) return true;
  auto take_first_clear = [&](const std::vector<std::vector<Eigen::VectorXd>>& routes, const char* name) {
    for (const auto& via : routes) {
      if (!first_hit(via)) {
        plan->transfer_via = via;
        plan->transfer_route = name;
        return true;
      }
    }
    return false;
  };
  // A palm pose moved from the one at posture q (warm start) by `shift` in R.
  auto shifted = [&](const Eigen::VectorXd& q, const Eigen::Vector3d& shift) -> std::optional<Eigen::VectorXd> {
    Eigen::Isometry3d X = chain.TipPose(q);
    X.translation() += shift;
    const IkResult r = solver.Solve(X, q);
    if (!Converged(r)) return std::nullopt;
    return r.q;
  };
  Eigen::Vector3d inward = -chain.TipPose(plan->q_pregrasp).translation();  // toward the robot's z axis
  inward.z() = 0;
  inward = inward.norm() > 1e-6 ? inward.normalized() : Eigen::Vector3d::Zero();
  // The postures above the transfer's end raised by transfer_raise_m[i], and the same pulled in
  // toward the robot; solved when first asked for (the routes from the current posture and from
  // home share them).
  struct RaisedEnd {
    std::optional<Eigen::VectorXd> above;
    std::optional<Eigen::VectorXd> inside;
  };
  std::vector<std::optional<RaisedEnd>> raised_ends(options.transfer_raise_m.size());
  auto raised_end = [&](size_t i) -> const RaisedEnd& {
    if (!raised_ends[i]) {
      const Eigen::Vector3d up = options.transfer_raise_m[i] * Eigen::Vector3d::UnitZ();
      raised_ends[i] =
          RaisedEnd{shifted(plan->q_pregrasp, up), shifted(plan->q_pregrasp, up + options.transfer_inward_m * inward)};
    }
    return *raised_ends[i];
  };
  // The raised routes from posture `from` (prefixed by `head`, the via postures that lead there),
  // raised by transfer_raise_m[i]: above the transfer's end, then down onto it; the same pulled in
  // toward the robot (the hand comes up inside the rack's edge, then moves out over it); above
  // `from`'s palm; and above it, then inside the end.
  auto raised_routes = [&](const std::vector<Eigen::VectorXd>& head, const Eigen::VectorXd& from, size_t i) {
    const auto& [above_end, inside_end] = raised_end(i);
    const auto above_from = shifted(from, options.transfer_raise_m[i] * Eigen::Vector3d::UnitZ());
    std::vector<std::vector<Eigen::VectorXd>> routes;
    auto add = [&](std::initializer_list<const std::optional<Eigen::VectorXd>*> via) {
      std::vector<Eigen::VectorXd> route = head;
      for (const auto* q : via) {
        if (!*q) return;
        route.push_back(**q);
      }
      routes.push_back(std::move(route));
    };
    add({&above_end});
    add({&inside_end});
    add({&above_from});
    add({&above_from, &inside_end});
    return routes;
  };
  for (size_t i = 0; i < raised_ends.size(); ++i) {
    if (take_first_clear(raised_routes({}, q_now, i), "raised")) return true;
  }
  // Joint by joint: after the look at the rack the hand hangs beside the torso, below the top of
  // the rack's ledge, and every route above could sweep the fingers through the ledge's near end
  // (7 of the 13 failed tool grasps of random-50 seeds 1 and 2 followed such blocks, the grasp
  // taking a pose that touched the rack instead). The arm bends up in front of the body first
  // (shoulder pitch, elbow, wrist to their end values), then swings out; or the arm moves to its
  // end posture first, the torso last.
  auto with = [&](const Eigen::VectorXd& base, const Eigen::VectorXd& from,
                  std::initializer_list<std::string_view> joints) {
    Eigen::VectorXd q = base;
    for (int i = 0; i < chain.num_joints(); ++i) {
      if (std::find(joints.begin(), joints.end(), chain.joint_names()[i]) != joints.end()) {
        q[chain.q_indices()[i]] = from[chain.q_indices()[i]];
      }
    }
    return q;
  };
  const Eigen::VectorXd& q_end = plan->q_pregrasp;
  if (take_first_clear(
          {{with(q_now, q_end, {"r_shoulder_pitch", "r_elbow", "r_wrist_prosup", "r_wrist_pitch", "r_wrist_yaw"})}},
          "arm_first") ||
      take_first_clear({{with(q_end, q_now, {"torso_pitch", "torso_roll", "torso_yaw"})}}, "torso_last")) {
    return true;
  }
  // Through the home posture, the hand in front of the chest: from the look at the rack, every
  // route above to the clear poses at a lying handle's centre (rot3) could be blocked, and the
  // grasp slid off the tool's balance or took a pose that pressed the open hand 20-25 mm into the
  // board, where the palm stopped 9-11 cm short of the handle (grasp-gt --from-rack-look, rot3: 13
  // of 32 grasped before this route, 22 with it; random-50 seeds 1-4: 176 -> 179 own grasps).
  Eigen::VectorXd home = q_now;
  for (const int index : chain.q_indices()) home[index] = q_home[index];
  if (take_first_clear({{home}}, "home")) return true;
  // From home on, the raised routes as from home itself (grasp-gt --from-rack-look: the hooks and
  // spatula_3 at pos1 reached the poses clear of the board only from above the palm at home, and
  // took poses 16-17 mm into the board instead, which dropped them).
  for (size_t i = 0; i < raised_ends.size(); ++i) {
    if (take_first_clear(raised_routes({home}, home, i), "home")) return true;
  }
  ++result->paths_blocked;
  result->last_blocked = Cat("the transfer would bring ", hit->link, " within ", options.obstacle_margin_m, " m of ",
                             hit->obstacle, " (at ", hit->p_R.transpose(), " m in R)");
  return false;
}

}  // namespace

GraspResult GraspHandle(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Isometry3d& X_RH,
                        const GraspOptions& options) {
  options.Validate();
  if (!X_RH.matrix().allFinite()) ThrowInvalid("GraspHandle: X_RH is not finite");
  const Eigen::Matrix3d R_RH = X_RH.linear();
  if (!(R_RH.transpose() * R_RH).isIdentity(1e-6) || R_RH.determinant() < 0) {
    ThrowInvalid("GraspHandle: the rotation part of X_RH is not a rotation");
  }
  const auto wall_start = std::chrono::steady_clock::now();
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  // Path waypoints are warm-started from their neighbour on the path: a restart from elsewhere
  // would land in another IK branch (a jump, not a straight line), so few restarts and a short
  // Ipopt run make a failing waypoint cheap.
  const IkOptions path_options = LimitedIk(options.ik, options.path_restarts, options.path_ipopt_iterations);
  const Eigen::VectorXd q_home = desc.HomeQ();
  CartesianSolver solver(chain, q_home, path_options);
  const std::vector<std::string> names = robot.JointNames();
  for (const auto* hand : {&desc.hand_open, &desc.hand_preshape, &desc.hand_closed}) {
    for (const auto& [joint, value] : *hand) {
      if (std::find(names.begin(), names.end(), joint) == names.end()) {
        ThrowInvalid("GraspHandle: the robot has no joint '", joint, "' of the hand");
      }
    }
  }
  const Eigen::VectorXd q_now = ModelQFrom(desc, names, robot.ReadEncoders());
  const ArmClearance clearance(desc, options.obstacles, desc.hand_open, options.obstacle_margin_m);
  const ArmClearance preshaped(desc, options.obstacles, desc.hand_preshape, options.obstacle_margin_m);
  const ArmClearance neighbours_open(desc, options.neighbours, desc.hand_open, options.obstacle_margin_m);
  const ArmClearance neighbours_preshaped(desc, options.neighbours, desc.hand_preshape, options.obstacle_margin_m);

  // The grasp frame G in P: origin on the grasp cylinder's axis, z along it, x toward the palm
  // normal's component orthogonal to it (any fixed choice works: the roll is sampled).
  const Eigen::Vector3d z_G = desc.grasp.axis.normalized();
  Eigen::Vector3d x_G = Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitZ().dot(z_G) * z_G;
  if (x_G.norm() < 1e-6) x_G = Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitX().dot(z_G) * z_G;
  x_G.normalize();
  Eigen::Isometry3d X_PG = Eigen::Isometry3d::Identity();
  X_PG.linear().col(0) = x_G;
  X_PG.linear().col(1) = z_G.cross(x_G);
  X_PG.linear().col(2) = z_G;
  X_PG.translation() = desc.grasp.center;
  const Eigen::Isometry3d X_GP = X_PG.inverse();

  const Eigen::Vector3d p_RH = X_RH.translation();
  Eigen::Vector3d outward(p_RH.x(), p_RH.y(), 0.0);  // from the robot's vertical axis to the handle
  outward = outward.norm() > 1e-6 ? outward.normalized() : Eigen::Vector3d(-1, 0, 0);

  GraspResult result;
  struct Candidate {
    Eigen::Isometry3d X_RP;
    double roll;
    bool flipped;
    double slide;
    IkResult ik;
    double depth = 0.0;  // touching candidates: how far the hand would reach into a fixture [m]
  };
  // Plans the whole path of one candidate (pre-grasp, staging, approach and lift waypoints);
  // false when a waypoint does not converge.
  std::string last_failure;
  auto plan_path = [&](const Candidate& c, Plan* out) -> bool {
    Plan p;
    p.X_RP = c.X_RP;
    p.roll = c.roll;
    p.flipped = c.flipped;
    p.slide = c.slide;
    p.rest_cost = c.ik.rest_cost;
    p.q_grasp = c.ik.q;
    Eigen::Isometry3d X_pre = c.X_RP;
    X_pre.translation() +=
        -options.pregrasp_back_m * c.X_RP.linear().col(2) + options.pregrasp_up_m * Eigen::Vector3d::UnitZ();
    // The pre-grasp warm-starts from the grasp posture so both lie in one IK branch.
    const IkResult pre = solver.Solve(X_pre, p.q_grasp);
    if (!Converged(pre)) {
      last_failure = Cat("pre-grasp IK: ", ToString(pre.status));
      return false;
    }
    // Staging pose: back toward the robot and up from the pre-grasp, so that the joint-space
    // transfer (which can swing the hand anywhere) ends clear of the rack; from there the hand
    // moves on straight lines. Without a reachable staging pose the transfer ends at the pre-grasp.
    Eigen::Isometry3d X_stage = X_pre;
    X_stage.translation() += -options.staging_back_m * outward + options.staging_up_m * Eigen::Vector3d::UnitZ();
    const IkResult stage = solver.Solve(X_stage, pre.q);
    bool ok = true;
    Eigen::VectorXd q = pre.q;
    if (Converged(stage)) {
      p.q_pregrasp = stage.q;
      q = stage.q;
      for (int i = 1; i <= options.approach_waypoints && ok; ++i) {
        Eigen::Isometry3d X = X_pre;
        const double s = static_cast<double>(i) / options.approach_waypoints;
        X.translation() = X_stage.translation() + s * (X_pre.translation() - X_stage.translation());
        const IkResult r = solver.Solve(X, q);
        if (!Converged(r)) {
          ok = false;
          break;
        }
        q = r.q;
        p.approach.push_back(q);
      }
    }
    if (!Converged(stage) || !ok) {
      ok = true;
      p.approach.clear();
      p.q_pregrasp = pre.q;
      q = pre.q;
    }
    for (int i = 1; i <= options.approach_waypoints && ok; ++i) {
      Eigen::Isometry3d X = c.X_RP;
      const double s = static_cast<double>(i) / options.approach_waypoints;
      X.translation() = X_pre.translation() + s * (c.X_RP.translation() - X_pre.translation());
      const IkResult r = solver.Solve(X, q);
      if (!Converged(r)) {
        last_failure = Cat("approach waypoint ", i, " IK: ", ToString(r.status));
        ok = false;
        break;
      }
      q = r.q;
      p.approach.push_back(q);
    }
    // Up and back toward the robot first (away from the board and its rail, which a tool lying
    // across the rack would catch when lifted straight up); straight up when that is out of
    // reach. The lift goes on in steps of lift_step_m up to lift_max_m while IK converges (a
    // tool that pivots in the grip hangs lower than the hand) and counts once it reached lift_m.
    for (const double retreat : {options.lift_retreat_m, 0.0}) {
      if (!ok || !p.lift.empty()) break;
      Eigen::VectorXd q_lift = q;
      std::vector<Eigen::VectorXd> lift;
      // Tools hang from a level handle (lying across the rack) and pivot in the grip: the extra
      // height over lift_m grows with how level the handle is (none for an upright handle, whose
      // tool comes up straight; lifting heavy upright tools higher loosens the grip).
      const double level = 1.0 - std::abs(R_RH.col(2).z());
      const double top = options.lift_m + std::max(0.0, options.lift_max_m - options.lift_m) * level;
      const int n = std::max(options.lift_waypoints, static_cast<int>(std::ceil(top / options.lift_step_m - 1e-9)));
      double reached = 0.0;
      for (int i = 1; i <= n; ++i) {
        Eigen::Isometry3d X = c.X_RP;
        const double s = static_cast<double>(i) / n;
        X.translation() += s * (top * Eigen::Vector3d::UnitZ() - retreat * outward);
        const IkResult r = solver.Solve(X, q_lift);
        if (!Converged(r)) {
          last_failure = Cat("lift waypoint ", i, " (retreat ", retreat, " m) IK: ", ToString(r.status), ", ",
                             r.position_error_m, " m off");
          break;
        }
        q_lift = r.q;
        lift.push_back(q_lift);
        reached = s * top;
      }
      if (reached >= options.lift_m - 1e-9) p.lift = std::move(lift);
    }
    ok = ok && !p.lift.empty();
    // Then back toward the robot, away from the board (optional: kept only when reachable).
    if (ok && options.retreat_m > 0) {
      Eigen::VectorXd q_back = p.lift.back();
      std::vector<Eigen::VectorXd> back;
      const Eigen::Isometry3d X_top = chain.TipPose(q_back);
      for (int i = 1; i <= 2; ++i) {
        Eigen::Isometry3d X = X_top;
        X.translation() -= options.retreat_m * i / 2.0 * outward;
        const IkResult r = solver.Solve(X, q_back);
        if (!Converged(r)) break;
        q_back = r.q;
        back.push_back(q_back);
      }
      if (back.size() == 2) p.lift.insert(p.lift.end(), back.begin(), back.end());
    }
    if (ok && !clearance.empty() &&
        !ClearTransfer(clearance, solver, chain, q_now, q_home, options, &p, &result)) {
      last_failure = result.last_blocked;
      ok = false;
    }
    if (ok) *out = std::move(p);
    return ok;
  };

  // Candidates are screened by a cheap solver (few restarts: most sampled poses are out of
  // reach, and a full failing solve costs ~30 restarts plus Ipopt); slide offsets are tried
  // nearest the handle centre first and the first offset with a complete path wins, lowest rest
  // cost first. Nothing moves before a plan is complete.
  const IkOptions screen_options =
      LimitedIk(options.ik, options.screening_restarts, options.screening_ipopt_iterations);
  const IkOptions fallback_options =
      LimitedIk(options.ik, options.fallback_restarts, options.fallback_ipopt_iterations);
  double best_error = std::numeric_limits<double>::infinity();
  const int steps = std::max(1, static_cast<int>(std::round(2 * M_PI / options.roll_step_rad)));
  std::vector<double> slides{0.0};
  // Every slide_step_m outward, then each end of the slide where the steps stop short of it (at
  // the arm's reach, the last millimetres along the handle count).
  const double widest = std::max(-options.handle_slide.min_m, options.handle_slide.max_m);
  for (double d = options.slide_step_m; d <= widest + options.slide_step_m - 1e-9; d += options.slide_step_m) {
    for (const double end : {options.handle_slide.min_m, options.handle_slide.max_m}) {
      const double along = std::copysign(std::min(d, std::abs(end)), end);
      if (std::abs(along) > d - options.slide_step_m + 1e-9) slides.push_back(along);
    }
  }
  const Eigen::Matrix3d R_flip = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  Plan plan;
  bool planned = false;
  // Pass 0: cheap screening; pass 1 (only when pass 0 found no reachable pose at all): a
  // stronger solver and a wider approach cone, for handles at the edge of the workspace.
  // Position error of each candidate's screening solve, by slide and sample index: the second
  // pass retries only those that came within fallback_max_error_m.
  std::map<std::pair<size_t, int>, double> screen_error;
  // Reachable grasp poses at which the open or the preshaped hand would touch a fixture (the
  // fingertips against the rack's board stop the palm short of the handle, and the closing
  // fingers then flick the tool off: 9 of the 10 empty hands and drops at pos1 in grasp-gt):
  // planned only when no other pose has a complete path, lowest rest cost first.
  std::vector<Candidate> touching;
  // Complete paths on which the hand would touch a neighbouring tool (options.neighbours): at the
  // staging pose, on the straight approach, at the grasp with the open or preshaped hand (an
  // approach through a tool hung in front of the chosen one pushes the hand onto that tool's
  // handle, and the hand closes on it). With whether the hand touches a fixture at the grasp
  // too; taken after all others, if at all.
  std::vector<std::pair<Plan, bool>> touching_neighbour;
  auto neighbour_hit = [&](const Plan& p) -> std::optional<ClearanceHit> {
    if (neighbours_open.empty()) return std::nullopt;
    if (auto hit = neighbours_open.Check(p.q_pregrasp)) return hit;
    Eigen::VectorXd from = p.q_pregrasp;
    for (const Eigen::VectorXd& q : p.approach) {
      if (auto hit = neighbours_open.CheckLine(from, q, options.transfer_check_step_rad)) return hit;
      from = q;
    }
    return HandHitAtGrasp(neighbours_open, neighbours_preshaped, p.q_grasp);
  };
  // Plans candidate c; true when its path is complete and keeps clear of the neighbours (a
  // complete path that does not is kept in touching_neighbour).
  auto plan_clear_of_neighbours = [&](const Candidate& c, bool fixture_too) {
    if (!plan_path(c, &plan)) return false;
    if (auto hit = neighbour_hit(plan)) {
      ++result.candidates_touching_neighbour;
      result.last_neighbour_touch = Cat(hit->link, " within ", options.obstacle_margin_m, " m of ", hit->obstacle);
      touching_neighbour.emplace_back(std::move(plan), fixture_too);
      plan = Plan{};
      return false;
    }
    return true;
  };
  for (int pass = 0; pass < 2 && !planned; ++pass) {
    if (pass == 1 && (result.candidates_feasible > 0 || options.fallback_restarts == 0)) break;
    CartesianSolver screen(chain, q_home, pass == 0 ? screen_options : fallback_options);
    const double min_cos = pass == 0 ? options.min_approach_cos : options.fallback_min_approach_cos;
    for (size_t i = 0; i < slides.size() && !planned; ++i) {
      std::vector<Candidate> feasible;
      for (int n = 0; n < 2 * steps; ++n) {
        const bool flipped = n >= steps;
        if ((options.axis_direction > 0 && flipped) || (options.axis_direction < 0 && !flipped)) continue;
        const double roll = (n % steps) * 2 * M_PI / steps;
        ++result.candidates;
        Eigen::Isometry3d X_RG = X_RH;
        X_RG.translation() += slides[i] * R_RH.col(2);
        X_RG.linear() = R_RH * RotZ(roll) * (flipped ? R_flip : Eigen::Matrix3d::Identity());
        const Eigen::Isometry3d X_RP = X_RG * X_GP;
        const Eigen::Vector3d approach_dir = X_RP.linear().col(2);  // palm -> handle
        if (approach_dir.dot(outward) < min_cos) continue;
        if (approach_dir.z() > options.max_approach_up_cos) continue;
        if (pass == 1) {
          const auto it = screen_error.find({i, n});
          // Not screened before: outside the first pass's approach cone, new here.
          if (it != screen_error.end() && it->second > options.fallback_max_error_m) continue;
        }
        IkResult ik = screen.Solve(X_RP, q_now);
        if (pass == 0) screen_error[{i, n}] = ik.position_error_m;
        best_error = std::min(best_error, ik.position_error_m);
        if (Converged(ik)) feasible.push_back({X_RP, roll, flipped, slides[i], std::move(ik)});
      }
      result.candidates_feasible += static_cast<int>(feasible.size());
      std::stable_sort(feasible.begin(), feasible.end(),
                       [](const Candidate& a, const Candidate& b) { return a.ik.rest_cost < b.ik.rest_cost; });
      for (Candidate& c : feasible) {
        if (!clearance.empty() && options.prefer_clear_hand) {
          const std::optional<ClearanceHit> hit = HandClosestAtGrasp(clearance, preshaped, c.ik.q);
          if (hit && hit->distance_m < options.obstacle_margin_m) {
            ++result.candidates_touching;
            result.last_touching = Cat(hit->link, " within ", options.obstacle_margin_m, " m of ", hit->obstacle);
            c.depth = -hit->distance_m;
            touching.push_back(std::move(c));
            continue;
          }
        }
        if (plan_clear_of_neighbours(c, false)) {
          planned = true;
          break;
        }
      }
    }
  }
  // Only grasp poses whose open or preshaped hand would touch a fixture: the hand stops where it
  // meets the fixture, short of the handle, and closes on it with the fingertips (rack corners:
  // 10-15 mm short in grasp-gt's rot3 cells, 7 of 16 dropped). Least deep first, in steps of
  // touching_depth_step_m; within a step the order above (slide nearest the centre, then rest cost).
  std::stable_sort(touching.begin(), touching.end(), [&](const Candidate& a, const Candidate& b) {
    return std::floor(a.depth / options.touching_depth_step_m) < std::floor(b.depth / options.touching_depth_step_m);
  });
  for (const Candidate& c : touching) {
    if (planned || !options.fixture_contact_allowed) break;
    planned = plan_clear_of_neighbours(c, true);
    result.hand_touches_fixture = planned;
    if (planned) result.hand_touch_depth_m = c.depth;
  }
  // Then, when allowed, a path on which the hand would touch a neighbouring tool: the first of
  // those clear of the fixtures at the grasp, else the first.
  if (!planned && options.neighbour_contact_allowed && !touching_neighbour.empty()) {
    const auto it = std::find_if(touching_neighbour.begin(), touching_neighbour.end(),
                                 [](const std::pair<Plan, bool>& p) { return !p.second; });
    if (it != touching_neighbour.end() || options.fixture_contact_allowed) {
      const auto& [chosen, fixture_too] = it != touching_neighbour.end() ? *it : touching_neighbour.front();
      plan = chosen;
      planned = true;
      result.hand_touches_neighbour = true;
      result.hand_touches_fixture = fixture_too;
    }
  }
  result.plan_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall_start).count();
  if (result.candidates_feasible == 0) {
    result.status = GraspStatus::kUnreachable;
    result.reason = Cat("no palm pose on the handle is reachable (", result.candidates,
                        " sampled; filters: approach from the robot side, not from below; handle at ", p_RH.transpose(),
                        " m in R; smallest IK position error ", best_error, " m)");
    return result;
  }
  if (!planned && !options.fixture_contact_allowed && !touching.empty()) {
    result.status = GraspStatus::kIkFailed;
    result.fixture_contact_refused = true;
    result.reason =
        Cat(result.candidates_feasible, " grasp poses reachable, none with a complete path on which the hand keeps ",
            options.obstacle_margin_m, " m clear of the fixtures at the grasp (last: ", result.last_touching, ")");
    return result;
  }
  if (!planned) {
    result.status = GraspStatus::kIkFailed;
    result.reason =
        touching_neighbour.empty()
            ? Cat(result.candidates_feasible, " grasp poses reachable but no complete path; last: ", last_failure)
            : Cat(result.candidates_feasible, " grasp poses reachable; on each of the ", touching_neighbour.size(),
                  " complete paths the hand would touch a neighbouring tool (last: ", result.last_neighbour_touch, ")");
    return result;
  }
  result.X_RP_grasp = plan.X_RP;
  result.roll_rad = plan.roll;
  result.axis_flipped = plan.flipped;
  result.slide_m = plan.slide;
  result.rest_cost = plan.rest_cost;
  if (options.accept_plan) {
    const std::string refused = options.accept_plan(plan.X_RP, plan.lift.empty() ? plan.q_grasp : plan.lift.back());
    if (!refused.empty()) {
      result.status = GraspStatus::kRejected;
      result.reason = Cat("the planned grasp was refused: ", refused);
      return result;
    }
  }

  // 1. Open hand, arm to the pre-grasp.
  double t0 = robot.Time();
  for (const Eigen::VectorXd& via : plan.transfer_via) {
    MoveJoints(robot, OpenHandGoal(chain, via, desc), options.transfer);
  }
  result.transfer_raised = !plan.transfer_via.empty();
  result.transfer_route = plan.transfer_route;
  const MotionResult transfer = MoveJoints(robot, OpenHandGoal(chain, plan.q_pregrasp, desc), options.transfer);
  result.transfer_s = robot.Time() - t0;
  if (options.on_stage) options.on_stage("staged");
  // The arm's arrival only: an opening finger may rest against the rack (it moves on with the hand).
  std::string worst;
  const double arm_error = transfer.reached ? 0.0 : ChainError(robot, chain, plan.q_pregrasp, &worst);
  if (arm_error > options.arm_arrival_tol) {
    result.status = GraspStatus::kMotionTimeout;
    result.reason = Cat("pre-grasp not reached: ", worst, " off by ", arm_error, " rad");
    return result;
  }

  // 2. Straight-line approach (contact with the handle may keep the last waypoint from being
  // reached exactly; the close decides).
  t0 = robot.Time();
  FollowWaypoints(robot, chain, plan.approach, options.approach);
  CompensateSag(robot, names, chain, plan.approach.back(), options.sag);
  result.approach_s = robot.Time() - t0;
  if (options.on_stage) options.on_stage("at_grasp");

  // 3. Preshape, then ramp to closed: the fingers stop on the handle while their targets go on
  // to hand_closed, which squeezes it (the servo error times kp is the grip force).
  t0 = robot.Time();
  MotionOptions preshape = options.approach;
  preshape.duration = options.preshape_time;
  preshape.timeout = 0.0;
  MoveJoints(robot, desc.hand_preshape, preshape);
  MotionOptions close = preshape;
  close.duration = options.close_time;
  MoveJoints(robot, desc.hand_closed, close);
  robot.Wait(options.settle_time);
  result.close_s = robot.Time() - t0;
  if (options.on_stage) options.on_stage("closed");
  // Empty hand: every long finger joint reached its closed target.
  if (const double gap = FingerGap(robot, desc); gap < options.empty_hand_tol) {
    result.status = GraspStatus::kEmptyHand;
    result.reason = Cat("fingers closed to within ", gap, " rad of hand_closed: nothing in the hand");
    return result;
  }

  // 4. Lift straight up and hold.
  t0 = robot.Time();
  FollowWaypoints(robot, chain, plan.lift, options.lift);
  CompensateSag(robot, names, chain, plan.lift.back(), options.sag);
  robot.Wait(options.hold_time);
  result.lift_s = robot.Time() - t0;
  if (options.on_stage) options.on_stage("lifted");
  // Closed on the handle, then all the way during the lift: the tool slipped out (a stick lying
  // on the rack's ledge, held near one end, fell in 1 of 50 random episodes).
  if (const double gap = FingerGap(robot, desc); gap < options.empty_hand_tol) {
    result.status = GraspStatus::kDropped;
    result.reason = Cat("fingers closed to within ", gap, " rad of hand_closed after the lift: the tool slipped out");
    return result;
  }
  result.status = GraspStatus::kGrasped;
  return result;
}

}  // namespace toolbench::control

namespace toolbench::control {
namespace {

void RequireHandJoints(const RobotInterface& robot, const robot::RobotDescription& desc, const char* function) {
  const std::vector<std::string> names = robot.JointNames();
  for (const auto* hand : {&desc.hand_open, &desc.hand_preshape, &desc.hand_closed}) {
    for (const auto& [joint, value] : *hand) {
      if (std::find(names.begin(), names.end(), joint) == names.end()) {
        ThrowInvalid(function, ": the robot has no joint '", joint, "' of the hand");
      }
    }
  }
}

void RequireFinite(const Eigen::Isometry3d& X, const char* function, const char* name) {
  if (!X.matrix().allFinite()) ThrowInvalid(function, ": ", name, " is not finite");
  const Eigen::Matrix3d R = X.linear();
  if (!(R.transpose() * R).isIdentity(1e-6) || R.determinant() < 0) {
    ThrowInvalid(function, ": the rotation part of ", name, " is not a rotation");
  }
}

// Largest joint difference between two postures [rad].
double JointStep(const Eigen::VectorXd& a, const Eigen::VectorXd& b) { return (a - b).cwiseAbs().maxCoeff(); }

// Straight-line IK waypoints from `from` to `to` (orientation of `to` throughout), warm-started
// from q; returns the waypoints that converged, stopping at the first that does not or that
// moves a joint by more than max_step [rad] from the previous posture (IK changed branch).
std::vector<Eigen::VectorXd> LineWaypoints(CartesianSolver& solver, const Eigen::Isometry3d& from,
                                           const Eigen::Isometry3d& to, int n, Eigen::VectorXd q,
                                           double max_step = std::numeric_limits<double>::infinity()) {
  std::vector<Eigen::VectorXd> path;
  for (int i = 1; i <= n; ++i) {
    Eigen::Isometry3d X = to;
    X.translation() = from.translation() + (static_cast<double>(i) / n) * (to.translation() - from.translation());
    const IkResult r = solver.Solve(X, q);
    if (!Converged(r) || JointStep(r.q, q) > max_step) break;
    q = r.q;
    path.push_back(q);
  }
  return path;
}

// The pose at fraction t of the way from `from` to `to` (position on the line, orientation
// slerped).
Eigen::Isometry3d Interpolate(const Eigen::Isometry3d& from, const Eigen::Isometry3d& to, double t) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::Quaterniond(from.linear()).slerp(t, Eigen::Quaterniond(to.linear())).toRotationMatrix();
  X.translation() = from.translation() + t * (to.translation() - from.translation());
  return X;
}

// Appends to *path the IK postures of a Cartesian path from `from` (posture q) to `to` over the
// fraction interval (t0, t1], n waypoints, each warm-started from the previous one. A waypoint more
// than max_step [rad] (any joint) from its predecessor is approached through the midpoint, up to
// `depth` halvings. Every posture must pass `ok`. False when a waypoint does not converge, stays
// discontinuous or fails `ok` (*path then holds the postures before it).
bool CartesianPath(CartesianSolver& solver, const Eigen::Isometry3d& from, const Eigen::Isometry3d& to, double t0,
                   double t1, int n, double max_step, int depth, const std::function<bool(const Eigen::VectorXd&)>& ok,
                   Eigen::VectorXd* q, std::vector<Eigen::VectorXd>* path) {
  for (int i = 1; i <= n; ++i) {
    const double t = t0 + (t1 - t0) * i / n;
    const IkResult r = solver.Solve(Interpolate(from, to, t), *q);
    if (Converged(r) && JointStep(r.q, *q) <= max_step) {
      if (!ok(r.q)) return false;
      *q = r.q;
      path->push_back(r.q);
      continue;
    }
    if (depth <= 0) return false;
    const double t_prev = t0 + (t1 - t0) * (i - 1) / n;
    if (!CartesianPath(solver, from, to, t_prev, t, 2, max_step, depth - 1, ok, q, path)) return false;
  }
  return true;
}

// The planning half of MovePalmThrough: IK postures of straight palm segments from q_now through
// points_R, the palm's orientation held loosely, each posture near the last; stops at the first
// point that does not plan (reason set).
struct PalmPath {
  std::vector<Eigen::VectorXd> path;
  int points_reached = 0;
  std::string reason;
};

PalmPath PlanPalmPath(const KinematicChain& chain, const Eigen::VectorXd& q_now,
                      const std::vector<Eigen::Vector3d>& points_R, const PalmPathOptions& options) {
  for (size_t i = 0; i < points_R.size(); ++i) {
    if (!points_R[i].allFinite()) ThrowInvalid("MovePalmThrough: points_R[", i, "] is not finite");
  }
  CartesianSolver solver(chain, q_now, options.ik);
  Eigen::Isometry3d from = chain.TipPose(q_now);
  Eigen::VectorXd q = q_now;
  PalmPath out;
  for (const Eigen::Vector3d& p : points_R) {
    if ((p - from.translation()).norm() < 1e-3) {  // already there
      ++out.points_reached;
      continue;
    }
    Eigen::Isometry3d to = from;
    to.translation() = p;
    const int n = std::max(1, static_cast<int>(std::ceil((p - from.translation()).norm() / options.step_m)));
    const std::vector<Eigen::VectorXd> segment = LineWaypoints(solver, from, to, n, q, options.max_joint_step_rad);
    out.path.insert(out.path.end(), segment.begin(), segment.end());
    if (static_cast<int>(segment.size()) < n) {
      out.reason = Cat("the palm path to (", p.transpose(), ") m in R stopped after waypoint ", segment.size(), " of ",
                       n, " (IK did not converge or changed branch)");
      break;
    }
    ++out.points_reached;
    from = to;
    q = segment.back();
  }
  return out;
}

// How far an object of `radius` at p may move along the unit direction u (both horizontal, in R)
// before its centre comes closer than radius + margin to an edge of `area` (+inf for an empty,
// unbounded area). An object that starts nearer an edge than that (the ball lies 5-7 cm from the
// table's far edge) may come kEdgeSlackM closer to it, never closer than its radius.
double DistanceToEdge(const Eigen::AlignedBox2d& area, double radius, double margin, const Eigen::Vector2d& p,
                      const Eigen::Vector2d& u) {
  constexpr double kEdgeSlackM = 0.02;
  if (area.isEmpty()) return std::numeric_limits<double>::infinity();
  double t = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 2; ++i) {
    if (std::abs(u[i]) < 1e-12) continue;
    const double to_edge = u[i] > 0 ? area.max()[i] - p[i] : p[i] - area.min()[i];
    const double closest = std::max(radius, std::min(radius + margin, to_edge - kEdgeSlackM));
    t = std::min(t, (to_edge - closest) / std::abs(u[i]));
  }
  return std::max(0.0, t);
}

}  // namespace

void PullOptions::Validate() const {
  auto fail = [](const char* field, double value, const char* expected) {
    ThrowInvalid("PullOptions: ", field, " = ", value, " (expected ", expected, ")");
  };
  if (!(clearance_m >= 0)) fail("clearance_m", clearance_m, ">= 0");
  if (!std::isfinite(height_offset_m)) fail("height_offset_m", height_offset_m, "finite");
  if (!(pull_length_m > 0)) fail("pull_length_m", pull_length_m, "> 0");
  if (!(support_edge_margin_m >= 0)) fail("support_edge_margin_m", support_edge_margin_m, ">= 0");
  if (!(support_travel_fraction > 0 && support_travel_fraction <= 1)) {
    fail("support_travel_fraction", support_travel_fraction, "in (0, 1]");
  }
  if (!support_xy.isEmpty() && !(support_xy.min().allFinite() && support_xy.max().allFinite())) {
    ThrowInvalid("PullOptions: support_xy = [", support_xy.min().transpose(), "] .. [",
                 support_xy.max().transpose(), "] (expected finite corners, or an empty box)");
  }
  if (!(max_drag_joint_step_rad > 0)) fail("max_drag_joint_step_rad", max_drag_joint_step_rad, "> 0");
  if (!(min_pull_fraction > 0 && min_pull_fraction <= 1)) fail("min_pull_fraction", min_pull_fraction, "in (0, 1]");
  if (!(max_complete_plans > 0)) fail("max_complete_plans", max_complete_plans, "> 0");
  if (!(approach_height_m >= 0)) fail("approach_height_m", approach_height_m, ">= 0");
  if (!(support_clearance_m >= 0)) fail("support_clearance_m", support_clearance_m, ">= 0");
  sag.Validate();
  if (!(start_step_m > 0)) fail("start_step_m", start_step_m, "> 0");
  if (!(max_start_distance_m > 0)) fail("max_start_distance_m", max_start_distance_m, "> 0");
  if (!(min_palm_height_m >= 0)) fail("min_palm_height_m", min_palm_height_m, ">= 0");
  if (!(start_tolerance_m >= 0)) fail("start_tolerance_m", start_tolerance_m, ">= 0");
  if (!(left_arm_clearance_m >= 0)) fail("left_arm_clearance_m", left_arm_clearance_m, ">= 0");
  if (!(min_elevation_rad >= -M_PI / 2 && min_elevation_rad <= max_elevation_rad)) {
    fail("min_elevation_rad", min_elevation_rad, "in [-pi/2, max_elevation_rad]");
  }
  if (!(max_elevation_rad <= M_PI / 2)) fail("max_elevation_rad", max_elevation_rad, "<= pi/2");
  if (!(elevation_step_rad > 0)) fail("elevation_step_rad", elevation_step_rad, "> 0");
  if (!(max_yaw_rad >= 0 && max_yaw_rad <= M_PI)) fail("max_yaw_rad", max_yaw_rad, "in [0, pi]");
  if (!(yaw_step_rad > 0)) fail("yaw_step_rad", yaw_step_rad, "> 0");
  if (!(max_roll_rad >= 0 && max_roll_rad <= M_PI)) fail("max_roll_rad", max_roll_rad, "in [0, pi]");
  if (!(roll_step_rad > 0)) fail("roll_step_rad", roll_step_rad, "> 0");
  if (descend_waypoints < 1) fail("descend_waypoints", descend_waypoints, ">= 1");
  if (!(clear_back_m >= 0)) fail("clear_back_m", clear_back_m, ">= 0");
  if (!(clear_up_m >= 0)) fail("clear_up_m", clear_up_m, ">= 0");
  if (!(carry_up_m >= 0)) fail("carry_up_m", carry_up_m, ">= 0");
  if (!(carry_back_m >= 0)) fail("carry_back_m", carry_back_m, ">= 0");
  if (transfer_waypoints < 2) fail("transfer_waypoints", transfer_waypoints, ">= 2");
  if (!(object_clearance_m >= 0)) fail("object_clearance_m", object_clearance_m, ">= 0");
  if (!(left_arm_object_radius_m >= 0)) fail("left_arm_object_radius_m", left_arm_object_radius_m, ">= 0");
  if (!(fixture_clearance_m >= 0)) fail("fixture_clearance_m", fixture_clearance_m, ">= 0");
  for (const ObstacleBox& box : fixtures) {
    if (!(box.X_RB.matrix().allFinite() && box.half.allFinite() && (box.half.array() > 0).all())) {
      ThrowInvalid("PullOptions: fixtures box '", box.name, "' has half extents (", box.half.transpose(),
                   ") or a pose that is not finite and positive");
    }
  }
  if (!(max_joint_step_rad > 0)) fail("max_joint_step_rad", max_joint_step_rad, "> 0");
  if (!(max_pull_turn_rad >= 0 && max_pull_turn_rad <= M_PI / 2)) fail("max_pull_turn_rad", max_pull_turn_rad, "in [0, pi/2]");
  if (!(pull_turn_step_rad > 0)) fail("pull_turn_step_rad", pull_turn_step_rad, "> 0");
  if (drag_waypoints < 2) fail("drag_waypoints", drag_waypoints, ">= 2");
  if (lift_waypoints < 1) fail("lift_waypoints", lift_waypoints, ">= 1");
  if (!(lift_back_m >= 0)) fail("lift_back_m", lift_back_m, ">= 0");
  if (!(lift_orientation_tolerance_rad >= ik.orientation_tolerance_rad && lift_orientation_tolerance_rad <= M_PI)) {
    fail("lift_orientation_tolerance_rad", lift_orientation_tolerance_rad, "in [ik.orientation_tolerance_rad, pi]");
  }
  if (!(empty_hand_tol > 0)) fail("empty_hand_tol", empty_hand_tol, "> 0");
  if (!(arm_arrival_tol > 0)) fail("arm_arrival_tol", arm_arrival_tol, "> 0");
  if (screening_restarts < 0) fail("screening_restarts", screening_restarts, ">= 0");
  if (screening_ipopt_iterations < 0) fail("screening_ipopt_iterations", screening_ipopt_iterations, ">= 0");
  if (path_restarts < 0) fail("path_restarts", path_restarts, ">= 0");
  transfer.Validate();
  waypoint.Validate();
  drag.Validate();
  ik.Validate();
}

const char* ToString(PullStatus status) {
  switch (status) {
    case PullStatus::kPulled: return "pulled";
    case PullStatus::kUnreachable: return "unreachable";
    case PullStatus::kIkFailed: return "ik_failed";
    case PullStatus::kMotionTimeout: return "motion_timeout";
    case PullStatus::kLostTool: return "lost_tool";
  }
  return "unknown";
}

bool PlanningFailed(PullStatus status) { return status == PullStatus::kUnreachable || status == PullStatus::kIkFailed; }

Eigen::Isometry3d HandleTowardEffector(const Eigen::Isometry3d& X_RH, const Eigen::Vector3d& p_R_effector) {
  if (!X_RH.matrix().allFinite() || !p_R_effector.allFinite()) {
    ThrowInvalid("HandleTowardEffector: X_RH or p_R_effector = (", p_R_effector.transpose(), ") is not finite");
  }
  if ((p_R_effector - X_RH.translation()).dot(X_RH.linear().col(2)) >= 0) return X_RH;
  Eigen::Isometry3d X = X_RH;
  X.linear() = X_RH.linear() * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  return X;
}

GraspResult GraspToolForAction(RobotInterface& robot, const robot::RobotDescription& desc,
                               const Eigen::Isometry3d& X_RH, const Eigen::Vector3d& p_R_effector,
                               const HandleSlide& slide, const GraspOptions& options) {
  slide.Validate("GraspToolForAction: slide");
  const Eigen::Isometry3d X_RH_toward = HandleTowardEffector(X_RH, p_R_effector);
  const Eigen::Vector3d z_H = X_RH.linear().col(2);
  GraspResult last;
  int candidates = 0;
  double plan_ms = 0.0;
  int paths_blocked = 0;
  std::string last_blocked;
  int touching_neighbour = 0;
  std::string last_neighbour_touch;
  bool fixture_contact = !options.clear_hand_first;
  auto attempt = [&](const Eigen::Isometry3d& X_RH_grasped, int direction, const HandleSlide& along) {
    GraspOptions o = options;
    o.axis_direction = direction;
    o.handle_slide = along;
    o.fixture_contact_allowed = fixture_contact && options.fixture_contact_allowed;
    last = GraspHandle(robot, desc, X_RH_grasped, o);
    candidates += last.candidates;
    plan_ms += last.plan_ms;
    paths_blocked += last.paths_blocked;
    if (!last.last_blocked.empty()) last_blocked = last.last_blocked;
    touching_neighbour += last.candidates_touching_neighbour;
    if (!last.last_neighbour_touch.empty()) last_neighbour_touch = last.last_neighbour_touch;
    last.candidates = candidates;
    last.plan_ms = plan_ms;
    last.paths_blocked = paths_blocked;
    last.last_blocked = last_blocked;
    last.candidates_touching_neighbour = touching_neighbour;
    last.last_neighbour_touch = last_neighbour_touch;
    last.slide_m = (X_RH_grasped.translation() - X_RH.translation()).dot(z_H) +
                   last.slide_m * X_RH_grasped.linear().col(2).dot(z_H);
    return !PlanningFailed(last.status);
  };
  // A transfer blocked on the way (the open hand caught on a neighbouring tool or the rack: the
  // grasp plans against the arm's reach, not against collisions) goes back to where it started
  // and the next grasp is tried.
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  const std::vector<std::string> names = robot.JointNames();
  const Eigen::VectorXd q_start = ModelQFrom(desc, names, robot.ReadEncoders());
  int blocked = 0;
  int regrasps = 0;
  std::string regrasp_reason;
  bool at_start = true;  // the arm where it started, the hand open (or as it was)
  auto back_off = [&] {
    MoveJoints(robot, OpenHandGoal(chain, q_start, desc), options.transfer);
    at_start = true;
  };
  // True when `last` is the answer; false to try the next grasp. A grip that let the tool slip
  // out (or closed on nothing) is tried again, up to max_regrasps times, the other way round.
  bool skip_direction = false;
  auto done = [&](const Eigen::Isometry3d& X_RH_grasped, int direction, const HandleSlide& along) {
    if (!attempt(X_RH_grasped, direction, along)) return false;
    at_start = false;
    const bool slipped = last.status == GraspStatus::kDropped || last.status == GraspStatus::kEmptyHand;
    if (slipped && regrasps < options.max_regrasps) {
      ++regrasps;
      regrasp_reason = Cat(ToString(last.status), ": ", last.reason);
      skip_direction = true;
    } else if (last.status == GraspStatus::kMotionTimeout) {
      ++blocked;
    } else {
      return true;
    }
    back_off();
    return false;
  };
  // A grasp that moved and failed leaves the hand open where the grasp started, out of the way of
  // a second look at the rack.
  auto finish = [&] {
    if (!at_start && last.status != GraspStatus::kGrasped) back_off();
    last.regrasps = regrasps;
    last.regrasp_reason = regrasp_reason;
    return last;
  };
  // A handle lying across the rack (within kLyingSin of horizontal: rot3) rests on the ledge
  // against the board, where the choked grasps close on nothing or let it roll out of the
  // fingertips: the whole handle first, as grasp-gt grasps it.
  constexpr double kLyingSin = 0.34;  // sin 20 deg
  const bool lying = std::abs(z_H.z()) < kLyingSin;
  const bool slides = slide.min_m < 0 || slide.max_m > 0;
  // The ways to grasp, in order; `group` 1 and 2 are the choked grasps of one way round, the rest
  // of which a slip skips.
  struct Way {
    Eigen::Isometry3d X_RH;
    int direction;
    HandleSlide along;
    int group;
  };
  std::vector<Way> ways;
  if (lying && slides) ways.push_back({X_RH, 0, slide, 0});
  // How far the grasp may move toward the handle's end away from the effector.
  const double away = X_RH_toward.linear().col(2).dot(z_H) > 0 ? -slide.min_m : slide.max_m;
  for (const int direction : {1, 0}) {
    for (const double choke : {0.6, 0.3, 0.0}) {
      Eigen::Isometry3d X = X_RH_toward;
      X.translation() -= choke * away * X_RH_toward.linear().col(2);
      ways.push_back({X, direction, HandleSlide{}, direction == 1 ? 1 : 2});
    }
  }
  if (!lying && slides) ways.push_back({X_RH, 0, slide, 3});
  // With clear_hand_first, every way is first planned with the hand clear of the fixtures; the
  // ways that had only poses touching one are planned again, in the same order, allowing them.
  std::vector<size_t> order(ways.size());
  for (size_t k = 0; k < ways.size(); ++k) order[k] = k;
  std::set<int> skipped;
  for (int sweep = 0; sweep < 2 && !order.empty(); ++sweep) {
    fixture_contact = sweep == 1 || !options.clear_hand_first;
    std::vector<size_t> refused;
    for (const size_t k : order) {
      const Way& w = ways[k];
      if (skipped.count(w.group) > 0) continue;
      skip_direction = false;
      if (done(w.X_RH, w.direction, w.along)) return finish();
      if (skip_direction && (w.group == 1 || w.group == 2)) skipped.insert(w.group);
      if (last.fixture_contact_refused) refused.push_back(k);
    }
    order = std::move(refused);
  }
  if (blocked > 0) last.reason += Cat(" (", blocked, " grasp transfers blocked on the way and backed off)");
  return finish();
}

const char* ToString(ToolAction action) {
  switch (action) {
    case ToolAction::kPull: return "pull";
    case ToolAction::kDragLeft: return "drag-left";
    case ToolAction::kDragRight: return "drag-right";
    case ToolAction::kPush: return "push";
  }
  return "unknown";
}

std::optional<ToolAction> ParseToolAction(std::string_view name) {
  for (const ToolAction a : {ToolAction::kPull, ToolAction::kDragLeft, ToolAction::kDragRight, ToolAction::kPush}) {
    if (name == ToString(a)) return a;
  }
  return std::nullopt;
}

Eigen::Vector3d ActionDirection(ToolAction action, const Eigen::Vector3d& p_RO) {
  if (!p_RO.allFinite()) ThrowInvalid("ActionDirection: p_RO = (", p_RO.transpose(), ") is not finite");
  const Eigen::Vector3d pull(-p_RO.x(), -p_RO.y(), 0.0);
  if (pull.norm() < 1e-3) {
    ThrowInvalid("ActionDirection: p_RO = (", p_RO.transpose(),
                 ") is on the robot's vertical axis (expected >= 1 mm from it horizontally)");
  }
  const Eigen::Vector3d u = pull.normalized();
  switch (action) {
    case ToolAction::kPull: return u;
    case ToolAction::kPush: return -u;
    case ToolAction::kDragRight: return Eigen::Vector3d::UnitZ().cross(u);
    case ToolAction::kDragLeft: return u.cross(Eigen::Vector3d::UnitZ());
  }
  ThrowInvalid("ActionDirection: unknown action ", static_cast<int>(action));
}

PullPlan PlanPull(const robot::RobotDescription& desc, const Eigen::VectorXd& q_model, const Eigen::Isometry3d& X_PT,
                  const ToolEffector& effector, const Eigen::Vector3d& p_RO, double object_radius,
                  const PullOptions& options) {
  options.Validate();
  RequireFinite(X_PT, "PullObject", "X_PT");
  if (q_model.size() != desc.model.num_q() || !q_model.allFinite()) {
    ThrowInvalid("PlanPull: q_model has ", q_model.size(), " values (expected ", desc.model.num_q(), ", all finite)");
  }
  if (!p_RO.allFinite()) ThrowInvalid("PullObject: p_RO = (", p_RO.transpose(), ") is not finite");
  if (!(object_radius > 0)) ThrowInvalid("PullObject: object_radius = ", object_radius, " (expected > 0)");
  if (!effector.center_T.allFinite()) {
    ThrowInvalid("PullObject: effector.center_T = (", effector.center_T.transpose(),
                 ") is not finite: the tool has no effector information");
  }
  if (!effector.direction_T.allFinite() || effector.direction_T.norm() < 1e-9) {
    ThrowInvalid("PullObject: effector.direction_T = (", effector.direction_T.transpose(),
                 ") is not a finite non-zero direction");
  }
  if (!(effector.half_thickness_m >= 0)) {
    ThrowInvalid("PullObject: effector.half_thickness_m = ", effector.half_thickness_m, " (expected >= 0)");
  }
  if (!effector.points_T.allFinite() || !effector.tool_points_T.allFinite()) {
    ThrowInvalid("PullObject: effector.points_T or effector.tool_points_T holds non-finite points");
  }
  if ((effector.points_T.cols() > 0) != (effector.tool_points_T.cols() > 0)) {
    ThrowInvalid("PullObject: effector.points_T has ", effector.points_T.cols(), " points, tool_points_T ",
                 effector.tool_points_T.cols(), " (expected both or neither)");
  }
  const auto wall_start = std::chrono::steady_clock::now();
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  CartesianSolver solver(chain, desc.HomeQ(), options.ik);
  CartesianSolver path_solver(chain, desc.HomeQ(), LimitedIk(options.ik, options.path_restarts, 0));
  const IkOptions screen_options =
      LimitedIk(options.ik, options.screening_restarts, options.screening_ipopt_iterations);
  CartesianSolver screen(chain, desc.HomeQ(), screen_options);
  IkOptions loose_options = screen_options;
  loose_options.position_tolerance_m = std::max(options.ik.position_tolerance_m, options.start_tolerance_m);
  CartesianSolver loose_screen(chain, desc.HomeQ(), loose_options);
  loose_options.presolve_restarts = options.ik.presolve_restarts;
  loose_options.max_iterations = options.ik.max_iterations;
  loose_options.ipopt_after_failed_presolve = options.ik.ipopt_after_failed_presolve;
  CartesianSolver start_solver(chain, desc.HomeQ(), loose_options);
  const Eigen::VectorXd& q_now = q_model;
  const Eigen::Isometry3d X_TP = X_PT.inverse();

  PullPlan plan;
  PullResult& result = plan.result;
  result.action = options.action;
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  if (Eigen::Vector2d(p_RO.x(), p_RO.y()).norm() < 1e-3) {
    result.status = PullStatus::kUnreachable;
    result.reason = "the object is on the robot's vertical axis: no action direction";
    return plan;
  }
  const Eigen::Vector3d u_straight = ActionDirection(options.action, p_RO);
  // The tool reaches out from the robot: orientations are sampled about the horizontal direction
  // from the robot's axis to the object, whatever the action.
  const Eigen::Vector3d out_straight = -ActionDirection(ToolAction::kPull, p_RO);
  const bool geometric = effector.points_T.cols() > 0 && effector.tool_points_T.cols() > 0;
  const double support_z = p_RO.z() - object_radius;
  std::vector<KinematicChain> left_arm;  // root -> each fixed left-arm link (torso joints only)
  for (const std::string& link : options.left_arm_links) left_arm.emplace_back(desc.model, desc.root_link, link);
  // True when the posture keeps the fixed left arm above the support (the table).
  auto left_arm_clear = [&](const Eigen::VectorXd& q) {
    for (const KinematicChain& c : left_arm) {
      if (c.TipPose(q).translation().z() < support_z + options.left_arm_clearance_m) return false;
    }
    return true;
  };
  auto path_clear = [&](const std::vector<Eigen::VectorXd>& path) {
    return std::all_of(path.begin(), path.end(), left_arm_clear);
  };
  // The transfer's checks: the fixed left arm stays above the object when near it, the tool above
  // the support and clear of the object (a subsample of its points keeps this cheap).
  Eigen::Matrix3Xd tool_sample;
  if (geometric) {
    const Eigen::Index stride = std::max<Eigen::Index>(1, effector.tool_points_T.cols() / 300);
    tool_sample.resize(3, (effector.tool_points_T.cols() + stride - 1) / stride);
    for (Eigen::Index i = 0, j = 0; i < effector.tool_points_T.cols(); i += stride, ++j) {
      tool_sample.col(j) = effector.tool_points_T.col(i);
    }
  }
  std::string transfer_failure;
  // Per fixture box, how near the tool may come on the transfer's turn and descent [m]: set where
  // the turn starts (plan_transfer).
  std::vector<double> fixture_floor(options.fixtures.size(), options.fixture_clearance_m);
  auto tool_fixture_distances = [&](const Eigen::Matrix3Xd& tool) {
    std::vector<double> nearest(options.fixtures.size(), std::numeric_limits<double>::infinity());
    for (size_t b = 0; b < options.fixtures.size(); ++b) {
      for (Eigen::Index i = 0; i < tool.cols(); ++i) {
        nearest[b] = std::min(nearest[b], BoxDistance(options.fixtures[b], tool.col(i)));
      }
    }
    return nearest;
  };
  auto transfer_clear = [&](const Eigen::VectorXd& q) {
    for (size_t i = 0; i < left_arm.size(); ++i) {
      const Eigen::Vector3d p = left_arm[i].TipPose(q).translation();
      if (Eigen::Vector2d(p.x() - p_RO.x(), p.y() - p_RO.y()).norm() < options.left_arm_object_radius_m &&
          p.z() < p_RO.z() + object_radius + options.left_arm_clearance_m) {
        transfer_failure = Cat("the left arm (", options.left_arm_links[i], ") would pass over the object");
        return false;
      }
    }
    if (!geometric) return true;
    const Eigen::Matrix3Xd tool = (chain.TipPose(q) * X_PT) * tool_sample;
    const double r_min = object_radius + options.object_clearance_m;
    for (Eigen::Index i = 0; i < tool.cols(); ++i) {
      if (tool(2, i) < support_z) {
        transfer_failure = "the tool would go below the object's support";
        return false;
      }
      if ((tool.col(i) - p_RO).squaredNorm() < r_min * r_min) {
        transfer_failure = "the tool would hit the object";
        return false;
      }
    }
    const std::vector<double> nearest = tool_fixture_distances(tool);
    for (size_t b = 0; b < nearest.size(); ++b) {
      if (nearest[b] < fixture_floor[b]) {
        transfer_failure = Cat("the tool would come within ", nearest[b], " m of ", options.fixtures[b].name);
        return false;
      }
    }
    return true;
  };
  // Joint-space straight line from a to b (not including a), in steps of at most
  // max_joint_step_rad, each posture checked by transfer_clear; false when one fails.
  auto connect = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, std::vector<Eigen::VectorXd>* path) {
    const int n = std::max(1, static_cast<int>(std::ceil(JointStep(a, b) / options.max_joint_step_rad)));
    for (int i = 1; i <= n; ++i) {
      const Eigen::VectorXd q = a + (static_cast<double>(i) / n) * (b - a);
      if (!transfer_clear(q)) return false;
      path->push_back(q);
    }
    return true;
  };
  // Transfer from q_now to q_above (see PullOptions::carry_up_m); false with transfer_failure.
  auto plan_transfer = [&](const Eigen::VectorXd& q_to, std::vector<Eigen::VectorXd>* path) {
    constexpr int kDepth = 3;
    path->clear();
    const Eigen::Isometry3d X_now = chain.TipPose(q_now);
    Eigen::Vector3d back(-X_now.translation().x(), -X_now.translation().y(), 0.0);
    back = back.norm() > 1e-6 ? back.normalized() : Eigen::Vector3d::Zero();
    Eigen::Isometry3d X_clear = X_now;
    X_clear.translation() += options.clear_back_m * back + options.clear_up_m * up;
    // Back and up off the rack, cut short where IK ends (the grasp may have left the arm there).
    const std::vector<Eigen::VectorXd> clear =
        LineWaypoints(path_solver, X_now, X_clear, 4, q_now, options.max_joint_step_rad);
    const Eigen::VectorXd q_clear = clear.empty() ? q_now : clear.back();
    if (geometric && !options.fixtures.empty()) {
      // A fixture the tool is already near (just off the rack) may not be approached further.
      const std::vector<double> start = tool_fixture_distances((chain.TipPose(q_clear) * X_PT) * tool_sample);
      for (size_t b = 0; b < start.size(); ++b) {
        fixture_floor[b] = std::min(options.fixture_clearance_m, start[b] - kFixtureSlackM);
      }
    }
    const Eigen::Isometry3d X_above = chain.TipPose(q_to);
    Eigen::Vector3d toward(-X_above.translation().x(), -X_above.translation().y(), 0.0);
    toward = toward.norm() > 1e-6 ? toward.normalized() : Eigen::Vector3d::Zero();
    std::vector<std::string> failures;
    for (const double f : {1.0, 0.5, 0.0}) {
      // The via posture is solved from the descent's side, so that it lies in the descent's IK
      // branch; the tool turns on the joint-space line to it, high above the table, where
      // transfer_clear checks it at every step.
      std::vector<Eigen::VectorXd> legs = clear;
      Eigen::VectorXd q_via = q_to;
      Eigen::Isometry3d X_via = X_above;
      if (f > 0) {
        X_via.translation() += f * (options.carry_up_m * up + options.carry_back_m * toward);
        const IkResult via = solver.Solve(X_via, q_to);
        if (!Converged(via)) {
          failures.push_back(Cat("via point ", f, ": IK ", ToString(via.status)));
          continue;
        }
        q_via = via.q;
      }
      // Turning the tool on a Cartesian path first (the hand on a line, orientation slerped), then
      // on a joint-space line (the hand swings more, but plans where the wrist limits cut the
      // Cartesian path).
      transfer_failure.clear();
      Eigen::VectorXd q_turn = q_clear;
      const size_t kept = legs.size();
      const bool cartesian = CartesianPath(path_solver, chain.TipPose(q_clear), X_via, 0.0, 1.0,
                                           options.transfer_waypoints, options.max_joint_step_rad, kDepth,
                                           transfer_clear, &q_turn, &legs) &&
                             JointStep(q_turn, q_via) <= options.max_joint_step_rad;
      if (cartesian) {
        legs.push_back(q_via);  // within max_joint_step_rad of the path's end
      } else {
        legs.resize(kept);
        transfer_failure.clear();
        if (!connect(q_clear, q_via, &legs)) {
          failures.push_back(Cat("turning the tool to via point ", f, ": ", transfer_failure));
          continue;
        }
      }
      Eigen::VectorXd q = q_via;
      if (f > 0 && (!CartesianPath(path_solver, X_via, X_above, 0.0, 1.0, 3, options.max_joint_step_rad, kDepth,
                                   transfer_clear, &q, &legs) ||
                    JointStep(q, q_to) > options.max_joint_step_rad)) {
        failures.push_back(Cat("down from via point ", f, ": ",
                               transfer_failure.empty() ? "IK or another IK branch" : transfer_failure));
        continue;
      }
      legs.push_back(q_to);
      *path = std::move(legs);
      return true;
    }
    transfer_failure.clear();
    for (const std::string& f : failures) transfer_failure += (transfer_failure.empty() ? "" : "; ") + f;
    return false;
  };
  std::vector<double> turns{0.0};
  for (double t = options.pull_turn_step_rad; t <= options.max_pull_turn_rad + 1e-9; t += options.pull_turn_step_rad) {
    turns.push_back(-t);  // -: toward the right shoulder (+y_R) for an object in front
    turns.push_back(t);
  }
  Eigen::VectorXd q_above;
  std::vector<Eigen::VectorXd> transfer, descend, drag, lift;
  std::string last_failure;
  double best_error = std::numeric_limits<double>::infinity();
  bool any_feasible = false;
  bool planned = false;
  bool any_on_support = false;  // a sampled orientation kept the object on support_xy
  for (const double turn : turns) {
  const Eigen::Vector3d u = Eigen::AngleAxisd(-turn, up) * u_straight;
  const Eigen::Vector3d out = Eigen::AngleAxisd(-turn, up) * out_straight;
  // The drag along u, cut where the object pushed along it would come too near the edge of its
  // support. (Cutting it also for a push along the working side's normal, drag (n . u) along n,
  // was tried: it cut rake_3's and spatula_1's drags to 9-10 cm, which then moved the ball 0.3
  // and 1.3 cm; the full drags had moved it 9 and 5 cm, on the table. pull-gt 29 -> 27 of 32.)
  const double min_pull_m = options.min_pull_fraction * options.pull_length_m;
  const double pull_length =
      std::min(options.pull_length_m, DistanceToEdge(options.support_xy, object_radius, options.support_edge_margin_m,
                                                   p_RO.head<2>(), u.head<2>()) /
                                          options.support_travel_fraction);
  if (pull_length < min_pull_m) {
    last_failure = Cat("a drag turned ", turn * 180 / M_PI, " deg would take the object off its support after ",
                       std::max(0.0, pull_length), " m");
    continue;
  }
  any_on_support = true;
  const double behind = object_radius + options.clearance_m + effector.half_thickness_m;
  const Eigen::Vector3d w = up.cross(u);  // horizontal, across the pull line
  // Effector centre at the start for a tool rotation R_RT; false when the tool cannot come down
  // behind the object without touching it, or its effector would not meet the object.
  // With the tool's points (in R, relative to the effector centre) and the effector centre at c:
  // -1 when a point would come down on the object (inflated by clearance_m) during the vertical
  // descent, 0 when the tool is clear but no effector point lies beyond the object within its
  // cross-section (near the pull line, between the support and the centre height), 1 when fine.
  auto start_clear = [&](const Eigen::Matrix3Xd& tool, const Eigen::Matrix3Xd& eff, const Eigen::Vector3d& c) {
    const double r_in = object_radius + options.clearance_m;
    for (Eigen::Index i = 0; i < tool.cols(); ++i) {
      const Eigen::Vector3d d = c + tool.col(i) - p_RO;
      const double rho2 = d.x() * d.x() + d.y() * d.y();
      if (rho2 < r_in * r_in && d.z() < std::sqrt(r_in * r_in - rho2)) return -1;
    }
    for (Eigen::Index i = 0; i < eff.cols(); ++i) {
      const Eigen::Vector3d d = c + eff.col(i) - p_RO;
      if (d.dot(u) < 0 && std::abs(d.dot(w)) < 0.5 * object_radius && d.z() < 0.5 * object_radius) return 1;
    }
    return 0;
  };
  auto place_start = [&](const Eigen::Matrix3d& R_RT, Eigen::Vector3d* p_RE) -> bool {
    if (!geometric) {
      *p_RE = p_RO - behind * u + options.height_offset_m * up;
      return true;
    }
    const Eigen::Matrix3Xd tool = R_RT * (effector.tool_points_T.colwise() - effector.center_T);
    const Eigen::Matrix3Xd eff = R_RT * (effector.points_T.colwise() - effector.center_T);
    // Lift the tool until its lowest point clears the support (table) the object rests on.
    const double z = std::max(p_RO.z() + options.height_offset_m,
                              support_z + options.support_clearance_m - tool.row(2).minCoeff());
    for (double t = object_radius; t <= options.max_start_distance_m + 1e-9; t += options.start_step_m) {
      const Eigen::Vector3d c(p_RO.x() - t * u.x(), p_RO.y() - t * u.y(), z);
      const int clear = start_clear(tool, eff, c);
      if (clear < 0) continue;
      if (clear == 0) return false;
      *p_RE = c;
      return true;
    }
    return false;
  };

  // Frames built in T from the palm -> effector line a_T and the working direction d_T, and in R
  // from the sampled line r and the pull direction u; the tool rotation maps one onto the other.
  const Eigen::Vector3d p_TP = X_TP.translation();
  Eigen::Vector3d a_T = effector.center_T - p_TP;
  const Eigen::Vector3d d_T = effector.direction_T.normalized();
  if (a_T.norm() < 1e-3) {
    ThrowInvalid("PullObject: the effector centre is at the palm (", a_T.norm(), " m away): not a tool");
  }
  a_T.normalize();
  auto frame = [](const Eigen::Vector3d& e1, const Eigen::Vector3d& hint) {
    Eigen::Vector3d e2 = hint - hint.dot(e1) * e1;
    if (e2.norm() < 1e-6) e2 = e1.unitOrthogonal();
    e2.normalize();
    Eigen::Matrix3d F;
    F.col(0) = e1;
    F.col(1) = e2;
    F.col(2) = e1.cross(e2);
    return F;
  };
  const Eigen::Matrix3d F_T = frame(a_T, d_T);

  struct Candidate {
    Eigen::Isometry3d X_RT;
    double elevation, yaw, roll;
    IkResult ik;
    double working_cos;  // working side's horizontal direction . u
  };
  std::vector<Candidate> feasible;
  for (double el = options.min_elevation_rad; el <= options.max_elevation_rad + 1e-9; el += options.elevation_step_rad) {
    for (double yaw = 0.0; yaw <= options.max_yaw_rad + 1e-9; yaw += options.yaw_step_rad) {
      for (const double ys : {1.0, -1.0}) {
        if (yaw == 0.0 && ys < 0) continue;
        for (double roll = 0.0; roll <= options.max_roll_rad + 1e-9; roll += options.roll_step_rad) {
          for (const double rs : {1.0, -1.0}) {
            if (roll == 0.0 && rs < 0) continue;
            ++result.candidates;
            const Eigen::Vector3d out_yaw = Eigen::AngleAxisd(ys * yaw, up) * out;
            const Eigen::Vector3d r = std::cos(el) * out_yaw - std::sin(el) * up;  // palm -> effector
            Eigen::Matrix3d F_R = frame(r, u);
            F_R = Eigen::AngleAxisd(rs * roll, r).toRotationMatrix() * F_R;
            Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();
            X_RT.linear() = F_R * F_T.transpose();
            // The working side's horizontal direction against the drag (PullResult::working_cos).
            const Eigen::Vector2d n_h = (X_RT.linear() * d_T).head<2>();
            const double along = n_h.norm() > 1e-6 ? n_h.normalized().dot(u.head<2>()) : 0.0;
            Eigen::Vector3d p_RE_start;
            if (!place_start(X_RT.linear(), &p_RE_start)) {
              ++result.candidates_blocked;
              continue;
            }
            X_RT.translation() = p_RE_start - X_RT.linear() * effector.center_T;
            const Eigen::Isometry3d X_RP = X_RT * X_TP;
            if (X_RP.translation().z() < support_z + options.min_palm_height_m) {
              ++result.candidates_blocked;
              continue;
            }
            IkResult ik = loose_screen.Solve(X_RP, q_now);
            best_error = std::min(best_error, ik.position_error_m);
            if (Converged(ik) && !left_arm_clear(ik.q)) {
              ++result.candidates_blocked;
              continue;
            }
            if (Converged(ik)) feasible.push_back({X_RT, el, ys * yaw, rs * roll, std::move(ik), along});
          }
        }
      }
    }
  }
  result.candidates_feasible += static_cast<int>(feasible.size());
  any_feasible = any_feasible || !feasible.empty();
  std::stable_sort(feasible.begin(), feasible.end(),
                   [](const Candidate& a, const Candidate& b) { return a.ik.rest_cost < b.ik.rest_cost; });
  const int min_drag = std::max(2, static_cast<int>(std::ceil(options.min_pull_fraction * options.drag_waypoints)));
  const Candidate* chosen = nullptr;
  // The complete plan with the longest drag so far (PullOptions::max_complete_plans).
  struct Best {
    Eigen::VectorXd q_above;
    std::vector<Eigen::VectorXd> transfer, descend, drag, lift;
    double drag_m = 0.0;
  } best;
  int complete = 0;
  for (const Candidate& c : feasible) {
    Eigen::Isometry3d X_RP_start = c.X_RT * X_TP;
    IkResult start = solver.Solve(X_RP_start, c.ik.q);
    if (!Converged(start) && options.start_tolerance_m > 0) {
      // At the edge of the workspace: accept a start up to start_tolerance_m off, planned from
      // where the palm really ends, if the tool there is still clear of the object and behind it.
      const IkResult loose = start_solver.Solve(X_RP_start, c.ik.q);
      if (Converged(loose)) {
        const Eigen::Isometry3d X_RT_real = chain.TipPose(loose.q) * X_PT;
        const Eigen::Vector3d c_real = X_RT_real * effector.center_T;
        const Eigen::Matrix3Xd tool = X_RT_real.linear() * (effector.tool_points_T.colwise() - effector.center_T);
        const Eigen::Matrix3Xd eff = X_RT_real.linear() * (effector.points_T.colwise() - effector.center_T);
        const bool above_support = c_real.z() + tool.row(2).minCoeff() >= support_z;
        if (!geometric || (above_support && start_clear(tool, eff, c_real) == 1)) {
          start = loose;
          X_RP_start = chain.TipPose(loose.q);
        }
      }
    }
    if (!Converged(start)) {
      last_failure = Cat("start IK: ", ToString(start.status));
      continue;
    }
    // From approach_height_m above the start, else from half of it (the edge of the workspace;
    // the descent check in place_start holds for any height above the object).
    Eigen::Isometry3d X_RP_above = X_RP_start;
    X_RP_above.translation() += options.approach_height_m * up;
    IkResult above = solver.Solve(X_RP_above, start.q);
    if (!Converged(above)) {
      X_RP_above.translation() = X_RP_start.translation() + 0.5 * options.approach_height_m * up;
      above = solver.Solve(X_RP_above, start.q);
    }
    if (!Converged(above)) {
      last_failure = Cat("above-start IK: ", ToString(above.status));
      continue;
    }
    descend = LineWaypoints(path_solver, X_RP_above, X_RP_start, options.descend_waypoints, above.q);
    if (static_cast<int>(descend.size()) < options.descend_waypoints || !left_arm_clear(above.q) ||
        !path_clear(descend)) {
      last_failure = Cat("descent waypoint ", descend.size() + 1, " IK failed");
      continue;
    }
    Eigen::Isometry3d X_RP_end = X_RP_start;
    X_RP_end.translation() += pull_length * u;
    drag.clear();
    Eigen::VectorXd q_drag = descend.back();
    const bool drag_complete = CartesianPath(path_solver, X_RP_start, X_RP_end, 0.0, 1.0, options.drag_waypoints,
                                             options.max_drag_joint_step_rad, 2, left_arm_clear, &q_drag, &drag);
    // How far along the pull the planned drag goes (halved steps make waypoints uneven).
    const double drag_m = drag_complete ? pull_length
                          : drag.empty()
                              ? 0.0
                              : std::clamp((chain.TipPose(drag.back()).translation() - X_RP_start.translation()).dot(u),
                                           0.0, pull_length);
    if (drag.size() < 2 || drag_m < pull_length * min_drag / options.drag_waypoints - 1e-6 ||
        drag_m < min_pull_m - 1e-6) {
      last_failure = Cat("drag IK ended after ", drag_m, " of ", pull_length, " m");
      continue;
    }
    Eigen::Isometry3d X_RP_last = X_RP_start;
    X_RP_last.translation() += drag_m * u;
    Eigen::Isometry3d X_RP_up = X_RP_last;
    X_RP_up.translation() += options.approach_height_m * up - options.lift_back_m * u;
    // The lift is cut where IK jumps branch: a large joint step swings the arm and the tool about
    // between two close poses, next to the ball (it flung one off the table). The drag is cut
    // only at max_drag_joint_step_rad after halving: cut at the lift's 0.3 rad, unhalved, it
    // halved pull-gt's successes (18 -> 12 of 32).
    IkOptions lift_ik = options.ik;
    lift_ik.orientation_tolerance_rad = options.lift_orientation_tolerance_rad;
    lift_ik.orientation_length_m = 0.02;  // position first: the palm must rise, it may tilt
    CartesianSolver lift_solver(chain, drag.back(), lift_ik);
    lift = LineWaypoints(lift_solver, X_RP_last, X_RP_up, options.lift_waypoints, drag.back(),
                         options.max_joint_step_rad);  // optional
    transfer_failure.clear();
    if (!plan_transfer(above.q, &transfer)) {
      last_failure = Cat("transfer: ", transfer_failure);
      continue;
    }
    ++complete;
    if (chosen == nullptr || drag_m > best.drag_m) {
      best = {above.q, transfer, descend, drag, lift, drag_m};
      chosen = &c;
    }
    if (drag_complete || complete >= options.max_complete_plans) break;
  }
  if (chosen != nullptr) {
    q_above = std::move(best.q_above);
    transfer = std::move(best.transfer);
    descend = std::move(best.descend);
    drag = std::move(best.drag);
    lift = std::move(best.lift);
    result.planned_drag_m = best.drag_m;
    result.planned_lift_m = options.approach_height_m * lift.size() / options.lift_waypoints;
    result.X_RT_start = chosen->X_RT;
    result.elevation_rad = chosen->elevation;
    result.yaw_rad = chosen->yaw;
    result.roll_rad = chosen->roll;
    result.pull_dir_R = u;
    result.pull_turn_rad = turn;
    result.working_cos = chosen->working_cos;
    const Eigen::Vector3d p_RE = chosen->X_RT * effector.center_T;
    result.start_distance_m = Eigen::Vector2d(p_RE.x() - p_RO.x(), p_RE.y() - p_RO.y()).norm();
    planned = true;
    break;
  }
  }  // turns
  result.plan_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall_start).count();
  if (!any_on_support) {
    result.status = PullStatus::kUnreachable;
    result.reason = Cat("every drag direction within ", options.max_pull_turn_rad * 180 / M_PI,
                        " deg of the action's would take the object at ", p_RO.transpose(),
                        " m in R off its support (", options.support_edge_margin_m, " m margin)");
    return plan;
  }
  if (!any_feasible) {
    result.status = PullStatus::kUnreachable;
    result.reason = Cat("no sampled tool orientation puts the effector behind the object (", result.candidates,
                        " sampled; object at ", p_RO.transpose(), " m in R; smallest palm IK error ", best_error,
                        " m)");
    return plan;
  }
  if (!planned) {
    result.status = PullStatus::kIkFailed;
    result.reason = Cat(result.candidates_feasible, " start poses reachable but no complete path; last: ", last_failure);
    return plan;
  }
  result.status = PullStatus::kPulled;
  plan.q_above = std::move(q_above);
  plan.transfer = std::move(transfer);
  plan.descend = std::move(descend);
  plan.drag = std::move(drag);
  plan.lift = std::move(lift);
  return plan;
}

PullResult PullObject(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Isometry3d& X_PT,
                      const ToolEffector& effector, const Eigen::Vector3d& p_RO, double object_radius,
                      const PullOptions& options) {
  options.Validate();
  RequireHandJoints(robot, desc, "PullObject");
  const std::vector<std::string> names = robot.JointNames();
  const Eigen::VectorXd q_now = ModelQFrom(desc, names, robot.ReadEncoders());
  PullPlan plan = PlanPull(desc, q_now, X_PT, effector, p_RO, object_radius, options);
  PullResult& result = plan.result;
  if (!plan.complete()) return result;
  const Eigen::VectorXd& q_above = plan.q_above;
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);

  const double t0 = robot.Time();
  // The transfer's waypoints are close together (PullOptions::max_joint_step_rad): each takes a
  // share of the transfer time.
  const MotionOptions step =
      SharedTime(options.waypoint, options.transfer.duration, options.waypoint.duration, plan.transfer.size());
  FollowWaypoints(robot, chain, plan.transfer, step);
  MoveJoints(robot, ChainGoal(chain, q_above), options.waypoint);
  // The servos sag under the tool's weight: a stick's effector came down 1.5 cm below the plan
  // and dug into the table, and the drag flicked the ball off it. The offsets that put the
  // encoders on the plan above the start are carried into the descent, the drag and the lift
  // (the load changes little over those few centimetres).
  // When the arm is stopped by something (its own body at the edge of the workspace), pushing
  // harder only adds to the error: then the plan's targets are kept.
  std::string worst;
  const double error_before = ChainError(robot, chain, q_above, &worst);
  Eigen::VectorXd sag = CompensateSag(robot, names, chain, q_above, options.sag);
  if (ChainError(robot, chain, q_above, &worst) > error_before) {
    sag.setZero();
    MoveJoints(robot, ChainGoal(chain, q_above), options.waypoint);
  }
  result.sag_offset_rad = sag.cwiseAbs().maxCoeff();
  auto offset = [&](std::vector<Eigen::VectorXd> path) {
    for (Eigen::VectorXd& q : path) q += sag;
    return path;
  };
  if (options.on_stage) options.on_stage("above_start");
  const double arm_error = ChainError(robot, chain, q_above, &worst);
  if (arm_error > options.arm_arrival_tol) {
    result.motion_s = robot.Time() - t0;
    result.status = PullStatus::kMotionTimeout;
    result.reason = Cat("above the start not reached: ", worst, " off by ", arm_error, " rad");
    return result;
  }
  // The descent stops at each waypoint and waits for the encoders, so the drag starts from rest.
  // Streamed like the other paths, the seeded rake_4 pull (tests/integration/pull_test.cpp) flung
  // the ball off the table during the drag, although the start looked the same in the pictures.
  for (const Eigen::VectorXd& q : offset(plan.descend)) MoveJoints(robot, ChainGoal(chain, q), options.waypoint);
  result.start_palm_error_m = (chain.TipPose(ModelQFrom(desc, names, robot.ReadEncoders())).translation() -
                               chain.TipPose(plan.descend.back()).translation())
                                  .norm();
  if (options.on_stage) options.on_stage("at_start");
  FollowWaypoints(robot, chain, offset(plan.drag), options.drag);
  if (options.on_stage) options.on_stage("dragged");
  FollowWaypoints(robot, chain, offset(plan.lift), options.waypoint);
  if (options.on_stage) options.on_stage("lifted");
  result.motion_s = robot.Time() - t0;
  const double gap = FingerGap(robot, desc);
  if (gap < options.empty_hand_tol) {
    result.status = PullStatus::kLostTool;
    result.reason = Cat("fingers closed to within ", gap, " rad of hand_closed: the tool left the hand");
    return result;
  }
  result.status = PullStatus::kPulled;
  return result;
}

}  // namespace toolbench::control

namespace toolbench::control {

void PutDownOptions::Validate() const {
  if (!tool_axis_T.allFinite()) {
    ThrowInvalid("PutDownOptions: tool_axis_T = (", tool_axis_T.transpose(), ") is not finite");
  }
  if (!(release_height_m >= 0)) ThrowInvalid("PutDownOptions: release_height_m = ", release_height_m, " (expected >= 0)");
  if (!(retreat_up_m >= 0)) ThrowInvalid("PutDownOptions: retreat_up_m = ", retreat_up_m, " (expected >= 0)");
  if (!(clear_height_m >= 0)) ThrowInvalid("PutDownOptions: clear_height_m = ", clear_height_m, " (expected >= 0)");
  if (!(keep_out_radius_m >= 0)) {
    ThrowInvalid("PutDownOptions: keep_out_radius_m = ", keep_out_radius_m, " (expected >= 0)");
  }
  if (!tool_points_T.allFinite()) ThrowInvalid("PutDownOptions: tool_points_T holds non-finite points");
  for (const Eigen::Vector3d& c : keep_out_R) {
    if (!c.allFinite()) ThrowInvalid("PutDownOptions: keep_out_R holds a non-finite centre");
  }
  clear.Validate();
  if (!(settle_time >= 0)) ThrowInvalid("PutDownOptions: settle_time = ", settle_time, " (expected >= 0)");
  transfer.Validate();
  open.Validate();
  ik.Validate();
}

PutDownResult PutDown(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Isometry3d& X_PT,
                      const Eigen::Vector3d& p_R_place, double tool_radius_m, const PutDownOptions& options) {
  options.Validate();
  RequireFinite(X_PT, "PutDown", "X_PT");
  if (!p_R_place.allFinite()) ThrowInvalid("PutDown: p_R_place = (", p_R_place.transpose(), ") is not finite");
  if (!(tool_radius_m >= 0)) ThrowInvalid("PutDown: tool_radius_m = ", tool_radius_m, " (expected >= 0)");
  RequireHandJoints(robot, desc, "PutDown");
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  CartesianSolver solver(chain, desc.HomeQ(), options.ik);
  const Eigen::VectorXd q_now = ModelQFrom(desc, robot.JointNames(), robot.ReadEncoders());
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  // Keep the tool's axis (options.tool_axis_T, else the grasp axis in P, along which a well-seated
  // handle runs) horizontal: rotate the current palm orientation so that it has no vertical
  // component, then sample yaws about z_R.
  const Eigen::Isometry3d X_RP_now = chain.TipPose(q_now);
  const Eigen::Vector3d axis_R = options.tool_axis_T.isZero()
                                     ? Eigen::Vector3d(X_RP_now.linear() * desc.grasp.axis.normalized())
                                     : Eigen::Vector3d(X_RP_now.linear() * X_PT.linear() * options.tool_axis_T.normalized());
  Eigen::Vector3d axis_flat(axis_R.x(), axis_R.y(), 0.0);
  if (axis_flat.norm() < 1e-6) axis_flat = Eigen::Vector3d::UnitX();
  const Eigen::Matrix3d R_level =
      Eigen::Quaterniond::FromTwoVectors(axis_R, axis_flat.normalized()).toRotationMatrix() * X_RP_now.linear();
  const Eigen::Vector3d p_grasp_P = desc.grasp.center;
  PutDownResult result;
  // With the tool's points known, the hand may also roll about the (level) handle axis: the tool
  // then turns about its handle, and its lowest point, whichever it is, ends release_height_m
  // above the surface. (Level, unrolled, no yaw planned for any place in 7 of 50 random episodes.)
  const bool have_points = options.tool_points_T.cols() > 0;
  const std::vector<double> rolls = have_points ? std::vector<double>{0.0, M_PI / 2, -M_PI / 2, M_PI} : std::vector<double>{0.0};
  const int yaws = 12;
  result.poses_sampled = yaws * static_cast<int>(rolls.size());
  // Every 8th tool point, checked along the way to the place: below keep_out_radius_m above a
  // keep-out centre, no point may come within keep_out_radius_m of it horizontally.
  Eigen::Matrix3Xd keep_out_points(3, 0);
  if (have_points && !options.keep_out_R.empty()) {
    keep_out_points.resize(3, (options.tool_points_T.cols() + 7) / 8);
    for (Eigen::Index i = 0; i < keep_out_points.cols(); ++i) keep_out_points.col(i) = options.tool_points_T.col(8 * i);
  }
  auto tool_clear = [&](const Eigen::VectorXd& q) {
    const Eigen::Matrix3Xd points = (chain.TipPose(q) * X_PT) * keep_out_points;
    for (const Eigen::Vector3d& c : options.keep_out_R) {
      for (Eigen::Index i = 0; i < points.cols(); ++i) {
        if (points(2, i) < c.z() + options.keep_out_radius_m &&
            Eigen::Vector2d(points(0, i) - c.x(), points(1, i) - c.y()).norm() < options.keep_out_radius_m) {
          return false;
        }
      }
    }
    return true;
  };
  for (int n = 0; n < result.poses_sampled; ++n) {
    const int k = n % yaws;
    const double roll = rolls[static_cast<size_t>(n / yaws)];
    const double yaw = (k % 2 == 0 ? 1 : -1) * ((k + 1) / 2) * M_PI / 6;
    Eigen::Isometry3d X_RP = Eigen::Isometry3d::Identity();
    X_RP.linear() = Eigen::AngleAxisd(yaw, up).toRotationMatrix() *
                    Eigen::AngleAxisd(roll, axis_flat.normalized()).toRotationMatrix() * R_level;
    // The grasp centre (handle axis) ends tool_radius + release height above the place.
    const Eigen::Vector3d p_axis = p_R_place + (tool_radius_m + options.release_height_m) * up;
    X_RP.translation() = p_axis - X_RP.linear() * p_grasp_P;
    if (have_points) {
      Eigen::Matrix3Xd points = (X_RP * X_PT) * options.tool_points_T;
      const double lift = p_R_place.z() + options.release_height_m - points.row(2).minCoeff();
      X_RP.translation().z() += lift;
      points.row(2).array() += lift;
      const Eigen::Vector2d centroid = points.topRows<2>().rowwise().mean();
      if (!options.support_xy.isEmpty() && !options.support_xy.contains(centroid)) {
        ++result.yaws_off_surface;
        continue;
      }
      bool near = false;
      for (const Eigen::Vector3d& c : options.keep_out_R) {
        near = near || (points.topRows<2>().colwise() - c.head<2>()).colwise().norm().minCoeff() < options.keep_out_radius_m;
      }
      if (near) {
        ++result.yaws_kept_out;
        continue;
      }
    }
    const IkResult low = solver.Solve(X_RP, q_now);
    if (!Converged(low)) continue;
    Eigen::Isometry3d X_above = X_RP;
    X_above.translation() += 0.10 * up;
    const IkResult above = solver.Solve(X_above, low.q);
    if (!Converged(above)) continue;
    const std::vector<Eigen::VectorXd> down = LineWaypoints(solver, X_above, X_RP, 3, above.q);
    if (down.size() < 3) continue;
    // Up to clear_height_m above the surface, across at that height to above the place, then
    // the joint-space turn into the pose above it (as far as the path goes: best effort).
    const double z_clear = p_R_place.z() + options.clear_height_m;
    Eigen::Vector3d p_up = X_RP_now.translation();
    p_up.z() = std::max(p_up.z(), z_clear);
    Eigen::Vector3d p_over = X_above.translation();
    p_over.z() = std::max(p_over.z(), z_clear);
    const PalmPath crossing = PlanPalmPath(chain, q_now, {p_up, p_over}, options.clear);
    if (keep_out_points.cols() > 0) {
      // The whole way, not only its ends, keeps the tool off the keep-out centres: a long tool
      // hanging from the hand swept down through the ball in the joint-space turn (episode/18).
      bool clear = std::all_of(crossing.path.begin(), crossing.path.end(), tool_clear) &&
                   std::all_of(down.begin(), down.end(), tool_clear);
      const Eigen::VectorXd& q_over = crossing.path.empty() ? q_now : crossing.path.back();
      const int n = std::max(2, static_cast<int>(std::ceil(JointStep(q_over, above.q) / 0.05)));
      for (int i = 1; clear && i < n; ++i) clear = tool_clear(q_over + (static_cast<double>(i) / n) * (above.q - q_over));
      if (!clear) {
        ++result.paths_kept_out;
        continue;
      }
    }
    if (!crossing.path.empty()) FollowWaypoints(robot, chain, crossing.path, options.clear.waypoint);
    MoveJoints(robot, ChainGoal(chain, above.q), options.transfer);
    MotionOptions step = options.open;
    step.duration = 0.4;
    step.timeout = 0.1;
    FollowWaypoints(robot, chain, down, step);
    MoveJoints(robot, desc.hand_open, options.open);
    robot.Wait(options.settle_time);
    // Straight up from where the open hand really is (position first: a rise planned from the
    // planned pose at the strict orientation was often cut short, and the hand's next move then
    // dragged the tool it had just let go of).
    const Eigen::Vector3d p_open =
        chain.TipPose(ModelQFrom(desc, robot.JointNames(), robot.ReadEncoders())).translation();
    const PalmPathResult rise = MovePalmThrough(robot, desc, {p_open + options.retreat_up_m * up}, options.clear);
    if (rise.points_reached == 0 && options.retreat_up_m > 0) {
      // Back through the descent's postures that lie above the hand now, to the pose above.
      const double z_now = chain.TipPose(ModelQFrom(desc, robot.JointNames(), robot.ReadEncoders())).translation().z();
      std::vector<Eigen::VectorXd> back;
      for (auto it = down.rbegin() + 1; it != down.rend(); ++it) {
        if (chain.TipPose(*it).translation().z() > z_now) back.push_back(*it);
      }
      back.push_back(above.q);
      FollowWaypoints(robot, chain, back, step);
      result.rise_retraced = true;
      result.rise_reason = rise.reason;
    }
    result.placed = true;
    result.X_RP = X_RP;
    return result;
  }
  result.reason = Cat("no palm yaw puts the tool above (", p_R_place.transpose(), ") m in R within reach (",
                      result.yaws_off_surface, " of ", result.poses_sampled, " palm poses would leave it off the surface, ",
                      result.yaws_kept_out, " too near a keep-out centre, ", result.paths_kept_out,
                      " with a way there that passes one)");
  return result;
}

void PalmPathOptions::Validate() const {
  if (!(step_m > 0)) ThrowInvalid("PalmPathOptions: step_m = ", step_m, " (expected > 0)");
  if (!(max_joint_step_rad > 0)) {
    ThrowInvalid("PalmPathOptions: max_joint_step_rad = ", max_joint_step_rad, " (expected > 0)");
  }
  waypoint.Validate();
  ik.Validate();
}

PalmPathResult MovePalmThrough(RobotInterface& robot, const robot::RobotDescription& desc,
                               const std::vector<Eigen::Vector3d>& points_R, const PalmPathOptions& options) {
  options.Validate();
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  PalmPath planned = PlanPalmPath(chain, ModelQFrom(desc, robot.JointNames(), robot.ReadEncoders()), points_R, options);
  PalmPathResult result;
  result.points_reached = planned.points_reached;
  result.reason = std::move(planned.reason);
  if (!planned.path.empty()) result.motion = FollowWaypoints(robot, chain, planned.path, options.waypoint);
  result.complete = result.points_reached == static_cast<int>(points_R.size()) &&
                    (planned.path.empty() || result.motion.reached);
  if (result.reason.empty() && !result.complete) {
    result.reason = Cat("the arm did not arrive: ", result.motion.worst_joint, " off by ", result.motion.max_error, " rad");
  }
  return result;
}

void BallGraspOptions::Validate() const {
  auto fail = [](const char* field, double value, const char* expected) {
    ThrowInvalid("BallGraspOptions: ", field, " = ", value, " (expected ", expected, ")");
  };
  if (!(lift_m >= 0)) fail("lift_m", lift_m, ">= 0");
  if (!(pregrasp_up_m >= 0)) fail("pregrasp_up_m", pregrasp_up_m, ">= 0");
  if (!(palm_gap_m >= 0)) fail("palm_gap_m", palm_gap_m, ">= 0");
  if (!(clear_height_m > 0)) fail("clear_height_m", clear_height_m, "> 0");
  if (!(roll_step_rad > 0 && roll_step_rad <= M_PI)) fail("roll_step_rad", roll_step_rad, "in (0, pi]");
  if (tilts_rad.empty()) ThrowInvalid("BallGraspOptions: tilts_rad is empty (expected at least one tilt)");
  for (double t : tilts_rad) {
    if (!(t >= 0 && t <= M_PI / 2)) fail("tilts_rad[i]", t, "in [0, pi/2]");
  }
  if (!(close_time > 0)) fail("close_time", close_time, "> 0");
  if (!(hold_time >= 0)) fail("hold_time", hold_time, ">= 0");
  if (!(empty_hand_tol > 0)) fail("empty_hand_tol", empty_hand_tol, "> 0");
  if (!(reach_rescue_max_error_m >= 0)) fail("reach_rescue_max_error_m", reach_rescue_max_error_m, ">= 0");
  if (grasp_ipopt_iterations < 0) fail("grasp_ipopt_iterations", grasp_ipopt_iterations, ">= 0");
  if (!(obstacle_margin_m >= 0)) fail("obstacle_margin_m", obstacle_margin_m, ">= 0");
  transfer.Validate();
  waypoint.Validate();
  clear_line.Validate();
  ik.Validate();
}

namespace {

// Palm poses for a whole-hand grasp of a ball: the palm normal z_P points at the ball centre from
// above (tilted toward the robot by `tilt`), rotated about it in steps; the ball's centre lies
// radius + gap in front of the palm.
std::vector<Eigen::Isometry3d> BallPalmPoses(const Eigen::Vector3d& p_RB, double radius, double tilt,
                                             const BallGraspOptions& options) {
  Eigen::Vector3d toward_robot(-p_RB.x(), -p_RB.y(), 0.0);
  toward_robot = toward_robot.norm() > 1e-6 ? toward_robot.normalized() : Eigen::Vector3d::UnitX();
  // z_P from the palm to the ball: down, and away from the robot when tilted (the hand comes from
  // the robot's side).
  const Eigen::Vector3d z_P = (-std::cos(tilt) * Eigen::Vector3d::UnitZ() - std::sin(tilt) * toward_robot).normalized();
  const Eigen::Vector3d x0 = (toward_robot - toward_robot.dot(z_P) * z_P).norm() > 1e-6
                                 ? (toward_robot - toward_robot.dot(z_P) * z_P).normalized()
                                 : z_P.unitOrthogonal();
  std::vector<Eigen::Isometry3d> poses;
  const int steps = std::max(1, static_cast<int>(std::round(2 * M_PI / options.roll_step_rad)));
  for (int k = 0; k < steps; ++k) {
    const Eigen::Vector3d x_P = Eigen::AngleAxisd(k * 2 * M_PI / steps, z_P) * x0;
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear().col(0) = x_P;
    X.linear().col(1) = z_P.cross(x_P);
    X.linear().col(2) = z_P;
    X.translation() = p_RB - (radius + options.palm_gap_m) * z_P;
    poses.push_back(X);
  }
  return poses;
}

}  // namespace

bool BallInReach(const robot::RobotDescription& desc, const Eigen::VectorXd& q_model, const Eigen::Vector3d& p_RB,
                 double radius, const BallGraspOptions& options) {
  options.Validate();
  if (!p_RB.allFinite()) ThrowInvalid("BallInReach: p_RB = (", p_RB.transpose(), ") is not finite");
  if (!(radius > 0)) ThrowInvalid("BallInReach: radius = ", radius, " (expected > 0)");
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  // A yes/no question over many poses: few restarts (a full failing solve costs ~30 of them).
  IkOptions quick = options.ik;
  quick.presolve_restarts = std::min(quick.presolve_restarts, 5);
  quick.max_iterations = std::min(quick.max_iterations, 30);
  std::vector<Eigen::Isometry3d> poses;
  for (double tilt : options.tilts_rad) {
    for (const Eigen::Isometry3d& X : BallPalmPoses(p_RB, radius, tilt, options)) poses.push_back(X);
  }
  // Pass 0: the pre-solve alone; pass 1: Ipopt's rescue for the near misses only, in the same order.
  IkOptions presolve_only = quick;
  presolve_only.ipopt_after_failed_presolve = false;
  CartesianSolver screen(chain, desc.HomeQ(), presolve_only);
  std::vector<double> error(poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    const IkResult r = screen.Solve(poses[i], q_model);
    if (Converged(r)) return true;
    error[i] = r.position_error_m;
  }
  if (!quick.ipopt_after_failed_presolve) return false;
  CartesianSolver solver(chain, desc.HomeQ(), quick);
  for (size_t i = 0; i < poses.size(); ++i) {
    if (error[i] <= options.reach_rescue_max_error_m && Converged(solver.Solve(poses[i], q_model))) return true;
  }
  return false;
}

bool BallWithinReach(const robot::RobotDescription& desc, const Eigen::VectorXd& q_model, const Eigen::Vector3d& p_RB,
                     double radius, double margin_m, const BallGraspOptions& options) {
  if (!(margin_m >= 0 && std::isfinite(margin_m))) ThrowInvalid("BallWithinReach: margin_m = ", margin_m, " (expected >= 0)");
  if (!p_RB.allFinite()) ThrowInvalid("BallWithinReach: p_RB = (", p_RB.transpose(), ") is not finite");
  Eigen::Vector3d outward(p_RB.x(), p_RB.y(), 0.0);
  outward = outward.norm() > 1e-6 ? outward.normalized() : Eigen::Vector3d::UnitX();
  return BallInReach(desc, q_model, p_RB + margin_m * outward, radius, options);
}

GraspResult GraspBall(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Vector3d& p_RB,
                      double radius, const BallGraspOptions& options) {
  options.Validate();
  if (!p_RB.allFinite()) ThrowInvalid("GraspBall: p_RB = (", p_RB.transpose(), ") is not finite");
  if (!(radius > 0)) ThrowInvalid("GraspBall: radius = ", radius, " (expected > 0)");
  RequireHandJoints(robot, desc, "GraspBall");
  const auto wall_start = std::chrono::steady_clock::now();
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  const IkOptions grasp_ik = LimitedIk(options.ik, options.ik.presolve_restarts, options.grasp_ipopt_iterations);
  CartesianSolver solver(chain, desc.HomeQ(), grasp_ik);
  // Short moves from where the hand is: no steps toward the rest posture, which jump IK branches
  // (0.76 rad for a 3 cm rise from a put-down posture).
  IkOptions local_options = grasp_ik;
  local_options.rest_iterations = 0;
  CartesianSolver local(chain, desc.HomeQ(), local_options);
  const Eigen::VectorXd q_now = ModelQFrom(desc, robot.JointNames(), robot.ReadEncoders());
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  GraspResult result;
  // The crossing (BallGraspOptions::clear_height_m): the palm keeps above `floor` while within
  // `near` of the ball horizontally, and nowhere dips below 3 cm above the ball's support (or
  // below where it starts, when that is lower: beside the table), on a joint-space line sampled
  // every ~0.05 rad. (The second condition is a safeguard: it changed none of 50 random episodes.)
  const double near = radius + options.clear_height_m;
  const double support_z = p_RB.z() - radius;
  auto crossing_clear = [&](const Eigen::VectorXd& a, const Eigen::VectorXd& b, double floor) {
    const int n = std::max(2, static_cast<int>(std::ceil(JointStep(a, b) / 0.05)));
    const double lowest = std::min(chain.TipPose(a).translation().z(), support_z + 0.03);
    for (int i = 1; i < n; ++i) {
      const Eigen::Vector3d p = chain.TipPose(a + (static_cast<double>(i) / n) * (b - a)).translation();
      if (Eigen::Vector2d(p.x() - p_RB.x(), p.y() - p_RB.y()).norm() < near && p.z() < floor) return false;
      if (p.z() < lowest) return false;
    }
    return true;
  };
  // The palm poses on the ball, in the order they are tried (tilt, then roll); each one's grasp
  // and pre-grasp IK is solved when a crossing height first reaches it and kept for the others.
  // The first pose with a complete path is taken, so the poses after it are never solved: most
  // fail, at ~80 ms a failing solve (bench ik), and solving all 36 up front cost ~2 s a grasp.
  struct Reach {
    Eigen::Isometry3d X, X_pre;
    IkResult grasp, pre;
    bool solved = false, converged = false;
  };
  std::vector<Reach> poses;
  for (const double tilt : options.tilts_rad) {
    for (const Eigen::Isometry3d& X : BallPalmPoses(p_RB, radius, tilt, options)) {
      Reach r;
      r.X = X;
      r.X_pre = X;
      r.X_pre.translation() += options.pregrasp_up_m * up - 0.5 * options.pregrasp_up_m * X.linear().col(2);
      poses.push_back(std::move(r));
    }
  }
  result.candidates = static_cast<int>(poses.size());
  auto reachable = [&](Reach& r) {
    if (!r.solved) {
      r.solved = true;
      r.grasp = solver.Solve(r.X, q_now);
      if (Converged(r.grasp)) {
        ++result.candidates_feasible;
        r.pre = solver.Solve(r.X_pre, r.grasp.q);
        r.converged = Converged(r.pre);
      }
    }
    return r.converged;
  };
  const Eigen::Isometry3d X_RP_now = chain.TipPose(q_now);
  const ArmClearance clearance(desc, options.obstacles, desc.hand_open, options.obstacle_margin_m);
  constexpr double kCheckStepRad = 0.05;
  Eigen::VectorXd q_pre, q_high, q_from = q_now;
  // cross: the crossing's postures when it goes on a straight palm line (empty: one joint move).
  std::vector<Eigen::VectorXd> rise, cross, down, approach, lift;
  bool planned = false;
  // Higher when the way there dips; lower at the edge of the workspace, where the pose above the
  // pre-grasp is out of reach (then the pre-grasp itself is the crossing's end).
  for (const double height : {options.clear_height_m, 2.0 * options.clear_height_m, 0.5 * options.clear_height_m}) {
    const double z_clear = p_RB.z() + radius + height;
    rise.clear();
    if (X_RP_now.translation().z() < z_clear) {
      Eigen::Isometry3d X_up = X_RP_now;
      X_up.translation().z() = z_clear;
      rise = LineWaypoints(local, X_RP_now, X_up, 3, q_now, 0.3);  // as high as IK goes
    }
    q_from = rise.empty() ? q_now : rise.back();
    for (Reach& r : poses) {
      if (!reachable(r)) continue;
      Eigen::Isometry3d X_high = r.X_pre;
      X_high.translation().z() = std::max(r.X_pre.translation().z(), z_clear);
      const IkResult high = solver.Solve(X_high, r.pre.q);
      if (!Converged(high) || !crossing_clear(q_from, high.q, z_clear - 0.5 * height)) continue;
      cross.clear();
      if (const auto hit = clearance.CheckLine(q_from, high.q, kCheckStepRad)) {
        ++result.paths_blocked;
        result.last_blocked = Cat(hit->link, " within ", options.obstacle_margin_m, " m of ", hit->obstacle,
                                  " on the joint-space crossing");
        // The palm on a straight line instead, each step (from q_line, the path's last posture
        // when CartesianPath asks) clear of the fixtures and the ball.
        Eigen::VectorXd q_line = q_from;
        auto line_clear = [&](const Eigen::VectorXd& q) {
          return !clearance.CheckLine(q_line, q, kCheckStepRad) && crossing_clear(q_line, q, z_clear - 0.5 * height);
        };
        if (!CartesianPath(local, chain.TipPose(q_from), X_high, 0.0, 1.0, 8, 0.3, 2, line_clear, &q_line, &cross) ||
            JointStep(q_line, high.q) > 0.3) {
          continue;
        }
        cross.push_back(high.q);
      }
      down = LineWaypoints(solver, X_high, r.X_pre, 3, high.q, 0.3);
      if (down.size() < 3) continue;
      approach = LineWaypoints(solver, r.X_pre, r.X, 4, down.back());
      if (approach.size() < 4) continue;
      Eigen::Isometry3d X_up = r.X;
      X_up.translation() += options.lift_m * up;
      lift = LineWaypoints(solver, r.X, X_up, 3, approach.back());
      if (lift.size() < 3) continue;
      q_pre = down.back();
      q_high = high.q;
      result.X_RP_grasp = r.X;
      result.rest_cost = r.grasp.rest_cost;
      planned = true;
      break;
    }
    if (planned) break;
  }
  result.plan_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall_start).count();
  if (!planned) {
    result.status = result.candidates_feasible == 0 ? GraspStatus::kUnreachable : GraspStatus::kIkFailed;
    result.reason = Cat("no complete top/side grasp path to the ball at (", p_RB.transpose(), ") m in R (",
                        result.candidates_feasible, " of ", result.candidates,
                        " palm poses reachable; none with a crossing that keeps the hand above the ball",
                        result.paths_blocked > 0 ? Cat(" and the arm clear of the fixtures; last: ", result.last_blocked)
                                                 : std::string(),
                        ")");
    return result;
  }
  double t0 = robot.Time();
  FollowWaypoints(robot, chain, rise, options.clear_line);
  if (cross.empty()) {
    MoveJoints(robot, OpenHandGoal(chain, q_high, desc), options.transfer);
  } else {
    std::vector<std::map<std::string, double>> goals;
    for (const Eigen::VectorXd& q : cross) goals.push_back(OpenHandGoal(chain, q, desc));
    // The transfer's time, shared by the line's waypoints.
    MoveThrough(robot, goals,
                SharedTime(options.transfer, options.transfer.duration, options.waypoint.duration, goals.size()));
  }
  FollowWaypoints(robot, chain, down, options.clear_line);
  result.transfer_s = robot.Time() - t0;
  std::string worst;
  const double arm_error = ChainError(robot, chain, q_pre, &worst);
  if (options.on_stage) options.on_stage("pre_grasp");
  if (arm_error > 0.08) {
    result.status = GraspStatus::kMotionTimeout;
    result.reason = Cat("pre-grasp not reached: ", worst, " off by ", arm_error, " rad");
    return result;
  }
  t0 = robot.Time();
  FollowWaypoints(robot, chain, approach, options.waypoint);
  result.approach_s = robot.Time() - t0;
  if (options.on_stage) options.on_stage("at_grasp");
  t0 = robot.Time();
  MotionOptions close = options.waypoint;
  close.duration = options.close_time;
  close.timeout = 0.0;
  MoveJoints(robot, desc.hand_closed, close);
  robot.Wait(0.3);
  result.close_s = robot.Time() - t0;
  if (options.on_stage) options.on_stage("closed");
  const double gap = FingerGap(robot, desc);
  if (gap < options.empty_hand_tol) {
    result.status = GraspStatus::kEmptyHand;
    result.reason = Cat("fingers closed to within ", gap, " rad of hand_closed: nothing in the hand");
    return result;
  }
  t0 = robot.Time();
  FollowWaypoints(robot, chain, lift, options.waypoint);
  robot.Wait(options.hold_time);
  result.lift_s = robot.Time() - t0;
  if (options.on_stage) options.on_stage("lifted");
  if (const double after = FingerGap(robot, desc); after < options.empty_hand_tol) {
    result.status = GraspStatus::kDropped;
    result.reason = Cat("fingers closed to within ", after, " rad of hand_closed after the lift: the ball slipped out");
    return result;
  }
  result.status = GraspStatus::kGrasped;
  return result;
}

void HandOverOptions::Validate() const {
  if (!(point_distance_m > 0)) ThrowInvalid("HandOverOptions: point_distance_m = ", point_distance_m, " (expected > 0)");
  if (!std::isfinite(point_height_m)) ThrowInvalid("HandOverOptions: point_height_m = ", point_height_m, " (expected finite)");
  if (!receive_at_R.allFinite() && !receive_at_R.array().isNaN().all()) {
    ThrowInvalid("HandOverOptions: receive_at_R = (", receive_at_R.transpose(),
                 ") (expected finite, or all NaN to hold the hand out toward the tool)");
  }
  if (!(wait_s >= 0)) ThrowInvalid("HandOverOptions: wait_s = ", wait_s, " (expected >= 0)");
  if (!(close_time > 0)) ThrowInvalid("HandOverOptions: close_time = ", close_time, " (expected > 0)");
  if (!(settle_time >= 0)) ThrowInvalid("HandOverOptions: settle_time = ", settle_time, " (expected >= 0)");
  transfer.Validate();
  hand.Validate();
  ik.Validate();
}

HandOverResult HandOver(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Vector3d& p_R_tool,
                        const PlaceToolInHand& place, const HandOverOptions& options) {
  options.Validate();
  if (!p_R_tool.allFinite()) ThrowInvalid("HandOver: p_R_tool = (", p_R_tool.transpose(), ") is not finite");
  if (!place) ThrowInvalid("HandOver: place is empty (expected the human's part of the hand-over)");
  RequireHandJoints(robot, desc, "HandOver");
  const KinematicChain chain = MakeRightArmChain(desc.model, desc.palm_frame);
  CartesianSolver solver(chain, desc.HomeQ(), options.ik);
  const Eigen::VectorXd q_now = ModelQFrom(desc, robot.JointNames(), robot.ReadEncoders());
  const bool receive_elsewhere = options.receive_at_R.allFinite();
  const Eigen::Vector3d toward = receive_elsewhere ? options.receive_at_R : p_R_tool;
  Eigen::Vector3d dir(toward.x(), toward.y(), 0.0);
  dir = dir.norm() > 1e-6 ? dir.normalized() : Eigen::Vector3d(-1, 0, 0);
  const Eigen::Vector3d p = receive_elsewhere
                                ? options.receive_at_R
                                : Eigen::Vector3d(options.point_distance_m * dir +
                                                  options.point_height_m * Eigen::Vector3d::UnitZ());
  // Palm up (z_P, palm -> held object, points up), tilted toward the robot as far as needed.
  HandOverResult result;
  Eigen::VectorXd q_goal;
  for (int tilt_deg = 0; tilt_deg <= 80 && q_goal.size() == 0; tilt_deg += 20) {
    const double tilt = tilt_deg * M_PI / 180.0;
    const Eigen::Vector3d z_P = (std::cos(tilt) * Eigen::Vector3d::UnitZ() - std::sin(tilt) * dir).normalized();
    for (int k = 0; k < 12; ++k) {
      const Eigen::Vector3d x0 = (dir - dir.dot(z_P) * z_P).normalized();
      const Eigen::Vector3d x_P = Eigen::AngleAxisd(k * M_PI / 6, z_P) * x0;
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.linear().col(0) = x_P;
      X.linear().col(1) = z_P.cross(x_P);
      X.linear().col(2) = z_P;
      X.translation() = p;
      const IkResult r = solver.Solve(X, q_now);
      if (Converged(r)) {
        q_goal = r.q;
        result.X_RP = X;
        break;
      }
    }
  }
  if (q_goal.size() == 0) {
    result.reason = Cat("no open-palm pose at (", p.transpose(), ") m in R toward the tool is reachable");
    return result;
  }
  MoveJoints(robot, OpenHandGoal(chain, q_goal, desc), options.transfer);
  robot.Wait(options.wait_s);
  // The palm pose the human sees: where the encoders put it (not the IK target).
  const Eigen::Isometry3d X_RP_now = chain.TipPose(ModelQFrom(desc, robot.JointNames(), robot.ReadEncoders()));
  result.X_RP = X_RP_now;
  place(X_RP_now);
  // Close at once (no preshape). The person holds the tool where they put it until the fingers
  // have closed on it, then lets go. Put on the open palm and left loose, the tool rolled as the
  // fingers swept it: 30-57 deg in the grip, and 8 of 50 random episodes lost it in the pull.
  MotionOptions close = options.hand;
  close.duration = options.close_time;
  MoveJoints(robot, desc.hand_closed, close, [&] { place(X_RP_now); });
  robot.Wait(options.settle_time);
  const double gap = FingerGap(robot, desc);
  result.holding = gap >= 0.05;
  if (!result.holding) result.reason = Cat("fingers closed to within ", gap, " rad of hand_closed: nothing in the hand");
  return result;
}

}  // namespace toolbench::control
