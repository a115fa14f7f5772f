#pragma once

#include <cmath>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/robot_interface.h"
#include "control/ik.h"
#include "control/motion.h"
#include "robot/robot_description.h"

namespace toolbench::control {

/// Options of GraspHandle. The defaults grasp library tools standing on the rack of
/// scenes/default.json (measured by `toolbench bench --protocol grasp-gt`).
struct GraspOptions {
  /// Rotation step of the palm about the handle axis when sampling palm poses [rad], in (0, pi].
  /// Both directions of the grasp axis along the handle are tried at every step.
  double roll_step_rad = 15.0 * M_PI / 180.0;
  /// How far the grasp centre may move along the handle axis, either way, from the handle centre
  /// [m], >= 0 (e.g. (handle length - grasp length) / 2 less a margin); 0 = at the centre only.
  /// Sampled every slide_step_m, the centre first; the lowest rest cost still decides.
  double handle_slide_m = 0.0;
  double slide_step_m = 0.02;  // [m], > 0
  /// Minimum cosine between the approach direction (palm normal z_P, from palm to handle) and the
  /// horizontal direction from the robot root's z axis to the handle, in [-1, 1]: rejects palm
  /// poses that reach around the handle from behind (through the board) or face the robot.
  double min_approach_cos = 0.2;
  /// Maximum cosine between the approach direction and the root's up axis z_R, in [-1, 1]:
  /// rejects palms that would come from below, through the ledge the tool stands on.
  double max_approach_up_cos = 0.5;
  double pregrasp_back_m = 0.07;  // pre-grasp offset back along -z_P from the grasp pose [m], >= 0
  double pregrasp_up_m = 0.02;    // extra pre-grasp offset up along z_R [m], >= 0
  /// Staging pose, where the joint-space transfer ends: the pre-grasp moved this far back toward
  /// the robot (horizontally) and up [m], >= 0; from there straight lines to pre-grasp and grasp.
  double staging_back_m = 0.10;
  double staging_up_m = 0.08;
  int approach_waypoints = 4;  // IK waypoints on the straight line pre-grasp -> grasp, >= 1
  double lift_m = 0.08;        // straight lift along z_R after closing [m], >= 0
  int lift_waypoints = 4;      // IK waypoints of the lift, >= 1
  /// When the straight lift is out of reach, the lift also moves this far back toward the robot
  /// (horizontally, toward the root's z axis) [m], >= 0.
  double lift_retreat_m = 0.06;
  /// After the lift, the hand moves this far back toward the robot (horizontally), pulling the
  /// tool off the board, when IK reaches it [m], >= 0.
  double retreat_m = 0.05;
  /// Servo sag compensation at the grasp and after the lift: iterations (>= 0) of adding the
  /// measured arm joint error to the targets, waiting sag_wait [s] (> 0) each, offsets capped
  /// at sag_max_offset_rad [rad] (>= 0).
  int sag_iterations = 3;
  double sag_wait = 0.15;
  double sag_max_offset_rad = 0.08;
  double preshape_time = 0.3;  // hand open -> preshape (thumb opposed) [s], > 0
  double close_time = 0.6;     // ramp preshape -> hand_closed [s], >= 0.5 (a slow squeeze)
  double settle_time = 0.3;    // wait after closing, before lifting [s], >= 0
  double hold_time = 0.5;      // wait after the lift before returning [s], >= 0
  /// A finger joint closer than this to its hand_closed target after closing means the hand
  /// closed on nothing [rad], > 0.
  double empty_hand_tol = 0.05;
  /// Largest arm joint error [rad] accepted at the pre-grasp before approaching, > 0 (servos sag
  /// under gravity; beyond this the motion counts as not done).
  double arm_arrival_tol = 0.05;
  MotionOptions transfer{2.0, 0.01, 0.02, 0.05, 2.0};  // home -> pre-grasp
  MotionOptions approach{0.4, 0.01, 0.02, 0.05, 0.3};  // each approach waypoint
  MotionOptions lift{0.4, 0.01, 0.02, 0.05, 0.1};      // each lift waypoint (hand joints never "arrive")
  IkOptions ik;  // the Cartesian solver's options (grasp, pre-grasp, approach and lift waypoints)
  /// Screening the sampled palm poses (most are out of reach) uses ik with fewer restarts and
  /// Ipopt iterations: presolve_restarts, >= 0, and max_iterations, > 0.
  int screening_restarts = 3;
  int screening_ipopt_iterations = 10;
  void Validate() const;  // throws std::invalid_argument naming the field and its value
};

/// How a grasp ended (an expected failure is a result, not an exception).
enum class GraspStatus {
  kGrasped,        // the hand closed on something and lifted it (the skill cannot see the tool:
                   // scoring checks ground truth)
  kUnreachable,    // no sampled palm pose on the handle is reachable by IK (or none passes the
                   // approach-direction filter)
  kIkFailed,       // a grasp pose was reachable but the pre-grasp, approach or lift waypoints were not
  kMotionTimeout,  // the arm did not arrive at the pre-grasp in time
  kEmptyHand,      // the fingers closed all the way: nothing between them
};

/// Human-readable name of a status ("grasped", "unreachable", ...).
const char* ToString(GraspStatus status);

/// Outcome of GraspHandle.
struct GraspResult {
  GraspStatus status = GraspStatus::kUnreachable;
  std::string reason;                                            // empty when grasped
  Eigen::Isometry3d X_RP_grasp = Eigen::Isometry3d::Identity();  // chosen palm pose at the grasp, in R
  double roll_rad = 0.0;        // chosen rotation of the palm about the handle axis [rad]
  bool axis_flipped = false;    // true when the grasp axis y_P runs along -z_H
  double slide_m = 0.0;         // chosen grasp centre along z_H from the handle centre [m]
  int candidates = 0;           // palm poses sampled
  int candidates_feasible = 0;  // of those, passing the filters with a converged grasp IK
  double rest_cost = 0.0;       // IK rest cost of the chosen grasp posture [1]
  double plan_ms = 0.0;         // wall time of choosing and planning (all IK) [ms], informational
  double transfer_s = 0.0;      // robot time: to the pre-grasp [s]
  double approach_s = 0.0;      // robot time: pre-grasp -> grasp [s]
  double close_s = 0.0;         // robot time: preshape, close, settle [s]
  double lift_s = 0.0;          // robot time: lift and hold [s]
};

/// Grasps a handle and lifts it with the right hand (torso + right arm chain to the palm frame):
///  1. samples palm poses P that put the hand's grasp cylinder (desc.grasp: centre and axis in P)
///     on the handle axis: both axis directions times rotations about the handle every
///     roll_step_rad, at grasp centres slid along the handle (handle_slide_m, centre first);
///     drops those whose approach direction fails the filters, screens the rest with a cheap IK
///     (CartesianSolver, rest posture desc.HomeQ(), warm start = the current encoders);
///  2. for the first slide offset that has any, takes the reachable poses by increasing IK rest
///     cost and plans the path: pre-grasp (pregrasp_back_m behind along -z_P, pregrasp_up_m
///     above), staging pose (further back and up), straight-line IK waypoints staging ->
///     pre-grasp -> grasp and grasp -> lift_m straight up (or up and back, lift_retreat_m, at the
///     edge of the workspace), each solve warm-started from the previous posture. The first
///     complete path wins; nothing moves before one is found;
///  3. opens the hand and moves (MoveJoints, joint space) to the staging pose, follows the
///     waypoints to the grasp, preshapes the hand, ramps it to desc.hand_closed over close_time,
///     checks the fingers stopped on something, lifts along the waypoints and holds hold_time.
/// The hold is by contact forces only. `X_RH` is the handle frame in R: origin at the handle
/// centre, z along the handle axis (its sign does not matter). Takes 2-5 s of wall time, most
/// of it IK screening when the handle is at the edge of the workspace.
/// Throws std::invalid_argument for bad options, a non-finite X_RH or one whose rotation part is
/// not a rotation, and when desc has no right-arm chain or robot lacks a joint of desc's hand.
GraspResult GraspHandle(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Isometry3d& X_RH,
                        const GraspOptions& options = {});

}  // namespace toolbench::control
