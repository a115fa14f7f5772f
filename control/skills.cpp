#include "control/skills.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "common/check.h"
#include "control/kinematics.h"

namespace toolbench::control {
namespace {

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

// Position servos sag under gravity and load (steady-state error = torque / kp). Adds the
// measured error of the chain joints to their targets, a few times, so that the encoders (and
// hence the hand) end where IK put them. Uses encoders only, as a real robot could.
void CompensateSag(RobotInterface& robot, const std::vector<std::string>& names, const KinematicChain& chain,
                   const Eigen::VectorXd& q_model_goal, int iterations, double wait, double max_offset) {
  std::vector<Eigen::Index> index(chain.num_joints());
  for (int i = 0; i < chain.num_joints(); ++i) {
    index[i] = std::find(names.begin(), names.end(), chain.joint_names()[i]) - names.begin();
  }
  for (int k = 0; k < iterations; ++k) {
    const Eigen::VectorXd enc = robot.ReadEncoders();
    Eigen::VectorXd target = robot.PositionTargets();
    for (int i = 0; i < chain.num_joints(); ++i) {
      const double goal = q_model_goal[chain.q_indices()[i]];
      const double offset = target[index[i]] - goal + (goal - enc[index[i]]);
      target[index[i]] = goal + std::clamp(offset, -max_offset, max_offset);
    }
    robot.SetPositionTargets(target);
    robot.Wait(wait);
  }
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
  std::vector<Eigen::VectorXd> approach;  // staging (exclusive) -> pre-grasp -> grasp (inclusive)
  std::vector<Eigen::VectorXd> lift;
};

bool Converged(const IkResult& r) { return r.status == IkStatus::kConverged; }

}  // namespace

void GraspOptions::Validate() const {
  auto fail = [](const char* field, double value, const char* expected) {
    ThrowInvalid("GraspOptions: ", field, " = ", value, " (expected ", expected, ")");
  };
  if (!(handle_slide_m >= 0)) fail("handle_slide_m", handle_slide_m, ">= 0");
  if (!(slide_step_m > 0)) fail("slide_step_m", slide_step_m, "> 0");
  if (!(roll_step_rad > 0 && roll_step_rad <= M_PI)) fail("roll_step_rad", roll_step_rad, "in (0, pi]");
  if (!(min_approach_cos >= -1 && min_approach_cos <= 1)) fail("min_approach_cos", min_approach_cos, "in [-1, 1]");
  if (!(max_approach_up_cos >= -1 && max_approach_up_cos <= 1)) {
    fail("max_approach_up_cos", max_approach_up_cos, "in [-1, 1]");
  }
  if (!(pregrasp_back_m >= 0)) fail("pregrasp_back_m", pregrasp_back_m, ">= 0");
  if (!(pregrasp_up_m >= 0)) fail("pregrasp_up_m", pregrasp_up_m, ">= 0");
  if (!(staging_back_m >= 0)) fail("staging_back_m", staging_back_m, ">= 0");
  if (!(staging_up_m >= 0)) fail("staging_up_m", staging_up_m, ">= 0");
  if (approach_waypoints < 1) fail("approach_waypoints", approach_waypoints, ">= 1");
  if (!(lift_m >= 0)) fail("lift_m", lift_m, ">= 0");
  if (lift_waypoints < 1) fail("lift_waypoints", lift_waypoints, ">= 1");
  if (!(lift_retreat_m >= 0)) fail("lift_retreat_m", lift_retreat_m, ">= 0");
  if (!(preshape_time > 0)) fail("preshape_time", preshape_time, "> 0");
  if (!(close_time >= 0.5)) fail("close_time", close_time, ">= 0.5");
  if (!(settle_time >= 0)) fail("settle_time", settle_time, ">= 0");
  if (!(hold_time >= 0)) fail("hold_time", hold_time, ">= 0");
  if (!(empty_hand_tol > 0)) fail("empty_hand_tol", empty_hand_tol, "> 0");
  if (screening_restarts < 0) fail("screening_restarts", screening_restarts, ">= 0");
  if (screening_ipopt_iterations < 1) fail("screening_ipopt_iterations", screening_ipopt_iterations, "> 0");
  if (!(retreat_m >= 0)) fail("retreat_m", retreat_m, ">= 0");
  if (sag_iterations < 0) fail("sag_iterations", sag_iterations, ">= 0");
  if (!(sag_wait > 0)) fail("sag_wait", sag_wait, "> 0");
  if (!(sag_max_offset_rad >= 0)) fail("sag_max_offset_rad", sag_max_offset_rad, ">= 0");
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
  }
  return "unknown";
}

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
  CartesianSolver solver(chain, desc.HomeQ(), options.ik);
  const std::vector<std::string> names = robot.JointNames();
  for (const auto* hand : {&desc.hand_open, &desc.hand_preshape, &desc.hand_closed}) {
    for (const auto& [joint, value] : *hand) {
      if (std::find(names.begin(), names.end(), joint) == names.end()) {
        ThrowInvalid("GraspHandle: the robot has no joint '", joint, "' of the hand");
      }
    }
  }
  const Eigen::VectorXd q_now = ModelQFrom(desc, names, robot.ReadEncoders());

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
    // Straight up first; at the edge of the workspace, up and back toward the robot.
    for (const double retreat : {0.0, options.lift_retreat_m}) {
      if (!ok || !p.lift.empty()) break;
      Eigen::VectorXd q_lift = q;
      std::vector<Eigen::VectorXd> lift;
      for (int i = 1; i <= options.lift_waypoints; ++i) {
        Eigen::Isometry3d X = c.X_RP;
        const double s = static_cast<double>(i) / options.lift_waypoints;
        X.translation() += s * (options.lift_m * Eigen::Vector3d::UnitZ() - retreat * outward);
        const IkResult r = solver.Solve(X, q_lift);
        if (!Converged(r)) {
          last_failure = Cat("lift waypoint ", i, " (retreat ", retreat, " m) IK: ", ToString(r.status), ", ",
                             r.position_error_m, " m off");
          break;
        }
        q_lift = r.q;
        lift.push_back(q_lift);
      }
      if (static_cast<int>(lift.size()) == options.lift_waypoints) p.lift = std::move(lift);
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
    if (ok) *out = std::move(p);
    return ok;
  };

  // Candidates are screened by a cheap solver (few restarts: most sampled poses are out of
  // reach, and a full failing solve costs ~30 restarts plus Ipopt); slide offsets are tried
  // nearest the handle centre first and the first offset with a complete path wins, lowest rest
  // cost first. Nothing moves before a plan is complete.
  IkOptions screen_options = options.ik;
  screen_options.presolve_restarts = options.screening_restarts;
  screen_options.max_iterations = options.screening_ipopt_iterations;
  CartesianSolver screen(chain, desc.HomeQ(), screen_options);
  double best_error = std::numeric_limits<double>::infinity();
  const int steps = std::max(1, static_cast<int>(std::round(2 * M_PI / options.roll_step_rad)));
  std::vector<double> slides{0.0};
  for (double d = options.slide_step_m; d <= options.handle_slide_m + 1e-9; d += options.slide_step_m) {
    slides.push_back(-d);
    slides.push_back(d);
  }
  const Eigen::Matrix3d R_flip = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  Plan plan;
  bool planned = false;
  for (size_t i = 0; i < slides.size() && !planned; ++i) {
    std::vector<Candidate> feasible;
    for (int n = 0; n < 2 * steps; ++n) {
      const bool flipped = n >= steps;
      const double roll = (n % steps) * 2 * M_PI / steps;
      ++result.candidates;
      Eigen::Isometry3d X_RG = X_RH;
      X_RG.translation() += slides[i] * R_RH.col(2);
      X_RG.linear() = R_RH * RotZ(roll) * (flipped ? R_flip : Eigen::Matrix3d::Identity());
      const Eigen::Isometry3d X_RP = X_RG * X_GP;
      const Eigen::Vector3d approach_dir = X_RP.linear().col(2);  // palm -> handle
      if (approach_dir.dot(outward) < options.min_approach_cos) continue;
      if (approach_dir.z() > options.max_approach_up_cos) continue;
      IkResult ik = screen.Solve(X_RP, q_now);
      best_error = std::min(best_error, ik.position_error_m);
      if (Converged(ik)) feasible.push_back({X_RP, roll, flipped, slides[i], std::move(ik)});
    }
    result.candidates_feasible += static_cast<int>(feasible.size());
    std::stable_sort(feasible.begin(), feasible.end(),
                     [](const Candidate& a, const Candidate& b) { return a.ik.rest_cost < b.ik.rest_cost; });
    for (const Candidate& c : feasible) {
      if (plan_path(c, &plan)) {
        planned = true;
        break;
      }
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
  if (!planned) {
    result.status = GraspStatus::kIkFailed;
    result.reason =
        Cat(result.candidates_feasible, " grasp poses reachable but no complete path; last: ", last_failure);
    return result;
  }
  result.X_RP_grasp = plan.X_RP;
  result.roll_rad = plan.roll;
  result.axis_flipped = plan.flipped;
  result.slide_m = plan.slide;
  result.rest_cost = plan.rest_cost;

  // 1. Open hand, arm to the pre-grasp.
  double t0 = robot.Time();
  std::map<std::string, double> goal = ChainGoal(chain, plan.q_pregrasp);
  for (const auto& [joint, value] : desc.hand_open) goal[joint] = value;
  const MotionResult transfer = MoveJoints(robot, goal, options.transfer);
  result.transfer_s = robot.Time() - t0;
  if (!transfer.reached && transfer.max_error > options.arm_arrival_tol) {
    result.status = GraspStatus::kMotionTimeout;
    result.reason = Cat("pre-grasp not reached: ", transfer.worst_joint, " off by ", transfer.max_error, " rad");
    return result;
  }

  // 2. Straight-line approach (contact with the handle may keep the last waypoint from being
  // reached exactly; the close decides).
  t0 = robot.Time();
  for (const Eigen::VectorXd& q : plan.approach) MoveJoints(robot, ChainGoal(chain, q), options.approach);
  CompensateSag(robot, names, chain, plan.approach.back(), options.sag_iterations, options.sag_wait,
                options.sag_max_offset_rad);
  result.approach_s = robot.Time() - t0;

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
  {
    // Empty hand: every long finger joint reached its closed target.
    const Eigen::VectorXd enc = robot.ReadEncoders();
    double max_gap = 0.0;
    for (const auto& [joint, value] : desc.hand_closed) {
      if (joint.rfind("r_thumb", 0) == 0) continue;
      const auto it = std::find(names.begin(), names.end(), joint);
      max_gap = std::max(max_gap, std::abs(enc[it - names.begin()] - value));
    }
    if (max_gap < options.empty_hand_tol) {
      result.status = GraspStatus::kEmptyHand;
      result.reason = Cat("fingers closed to within ", max_gap, " rad of hand_closed: nothing in the hand");
      return result;
    }
  }

  // 4. Lift straight up and hold.
  t0 = robot.Time();
  for (const Eigen::VectorXd& q : plan.lift) MoveJoints(robot, ChainGoal(chain, q), options.lift);
  CompensateSag(robot, names, chain, plan.lift.back(), options.sag_iterations, options.sag_wait,
                options.sag_max_offset_rad);
  robot.Wait(options.hold_time);
  result.lift_s = robot.Time() - t0;
  result.status = GraspStatus::kGrasped;
  return result;
}

}  // namespace toolbench::control
