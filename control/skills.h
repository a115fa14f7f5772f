#pragma once

#include <cmath>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/robot_interface.h"
#include "control/clearance.h"
#include "control/ik.h"
#include "control/motion.h"
#include "robot/robot_description.h"

namespace toolbench::control {

/// Servo sag compensation: the position servos sag under gravity and load (steady-state error =
/// torque / kp); `iterations` times (>= 0) the measured arm joint error is added to the targets,
/// waiting wait_s [s] (> 0) each, the offsets capped at max_offset_rad [rad] (>= 0).
struct SagCompensation {
  int iterations = 3;
  double wait_s = 0.15;
  double max_offset_rad = 0.08;
  void Validate() const;  // throws std::invalid_argument naming the field
};

/// How far a grasp centre may move along a handle's axis z_H from the handle's centre [m]:
/// min_m <= 0 <= max_m, both finite. Symmetric(s) is [-s, s], e.g. (handle length - grasp length)
/// / 2 less a margin; a tool that stays a bar past its handle (a shovel's neck) reaches further on
/// that side (app's GripSlide).
struct HandleSlide {
  double min_m = 0.0;  // toward -z_H, <= 0
  double max_m = 0.0;  // toward +z_H, >= 0
  static HandleSlide Symmetric(double s) { return {-s, s}; }
  bool operator==(const HandleSlide&) const = default;
  /// Throws std::invalid_argument "<field> = [min, max]: <field>.min_m = ..." naming the bad end.
  void Validate(const std::string& field) const;
};

/// Options of GraspHandle. The defaults grasp library tools standing on the rack of
/// scenes/default.json (measured by `toolbench bench --protocol grasp-gt`).
struct GraspOptions {
  /// Rotation step of the palm about the handle axis when sampling palm poses [rad], in (0, pi].
  /// Both directions of the grasp axis along the handle are tried at every step.
  double roll_step_rad = 15.0 * M_PI / 180.0;
  /// Where along the handle axis the grasp centre may move from the handle centre; {0, 0} = at
  /// the centre only. Sampled every slide_step_m, the centre first, then both ways outward; the
  /// lowest rest cost still decides.
  HandleSlide handle_slide;
  double slide_step_m = 0.02;  // [m], > 0
  /// Minimum cosine between the approach direction (palm normal z_P, from palm to handle) and the
  /// horizontal direction from the robot root's z axis to the handle, in [-1, 1]: rejects palm
  /// poses that reach around the handle from behind (through the board) or face the robot.
  double min_approach_cos = 0.2;
  /// Maximum cosine between the approach direction and the root's up axis z_R, in [-1, 1]:
  /// rejects palms that would come from below, through the ledge the tool stands on.
  double max_approach_up_cos = 0.5;
  /// Which way the hand's grasp axis y_P may run along the handle: 0 = either (the lowest rest
  /// cost decides), +1 = along +z_H only, -1 = along -z_H only. The pull wants the tool's effector
  /// on a given side of the hand.
  int axis_direction = 0;
  double pregrasp_back_m = 0.07;  // pre-grasp offset back along -z_P from the grasp pose [m], >= 0
  double pregrasp_up_m = 0.02;    // extra pre-grasp offset up along z_R [m], >= 0
  /// Staging pose, where the joint-space transfer ends: the pre-grasp moved this far back toward
  /// the robot (horizontally) and up [m], >= 0; from there straight lines to pre-grasp and grasp.
  double staging_back_m = 0.10;
  double staging_up_m = 0.08;
  int approach_waypoints = 4;  // IK waypoints on the straight line pre-grasp -> grasp, >= 1
  /// Smallest lift along z_R after closing [m], >= 0 (see lift_max_m, lift_retreat_m). More than
  /// the 5 cm success margin: tools lying across the rack pivot in the grip as they come up, so
  /// their origin rises less.
  double lift_m = 0.11;
  int lift_waypoints = 4;      // IK waypoints of the lift (at least), >= 1
  /// The lift goes on past lift_m, in straight steps of at most lift_step_m (> 0), while IK
  /// converges, up to lift_m + (lift_max_m - lift_m) * (1 - |cos(handle axis, z_R)|) [m], >= 0:
  /// a tool held by a level handle (lying across the rack) pivots in the grip and its far end
  /// hangs lower than the hand; heavy upright tools lifted higher than needed loosen the grip.
  double lift_max_m = 0.17;
  double lift_step_m = 0.03;
  /// The lift also moves this far back toward the robot (horizontally, toward the root's z
  /// axis), away from the board [m], >= 0; straight up when that is out of reach.
  double lift_retreat_m = 0.08;
  /// After the lift, the hand moves this far back toward the robot (horizontally), pulling the
  /// tool off the board, when IK reaches it [m], >= 0.
  double retreat_m = 0.05;
  SagCompensation sag;  // at the grasp and after the lift
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
  MotionOptions transfer{2.0, 0.01, 0.02, 0.05, 2.0, kTransferSpeed};  // home -> pre-grasp
  /// Fixed boxes of the workspace (table, rack: from the scene file, not perceived) that the
  /// forearm and the open hand must stay obstacle_margin_m [m] (>= 0) clear of on the joint-space
  /// transfer, checked every transfer_check_step_rad (> 0) of joint motion. A transfer that would
  /// pass through one is rerouted through via postures, for each of transfer_raise_m [m] in turn:
  /// above its end (then down onto it), above it and transfer_inward_m [m] (>= 0) closer to the
  /// robot (then out over the rack's edge), above the current palm, or the last two; then joint
  /// by joint, then through the home posture (see GraspResult::transfer_route); a transfer
  /// that stays blocked rejects the candidate. The straight lines from the staging pose on are not
  /// checked (a handle near the ledge puts the open thumb within a centimetre of it there).
  /// Empty = no check (the open hand can then catch on the rack's ledge and the transfer times
  /// out: 6 of 50 random episodes in session 9).
  std::vector<ObstacleBox> obstacles;
  double obstacle_margin_m = 0.0;
  /// With obstacles: grasp poses at which the open or the preshaped hand would come within
  /// obstacle_margin_m of one (the fingertips against the rack's board stop the palm short of the
  /// handle, and the closing fingers flick the tool off) are planned only when no other reachable
  /// pose, at any slide along the handle, has a complete path. false = rest cost alone decides.
  bool prefer_clear_hand = true;
  /// Those poses are tried least deep first: by how far the open or preshaped hand would reach
  /// into the fixture, in steps of this [m], > 0 (within a step: slide nearest the centre, then
  /// rest cost). Infinity: slide and rest cost alone.
  double touching_depth_step_m = 0.005;
  /// Things the hand should leave alone but may touch when nothing else is left: the other tools
  /// on the rack, as boxes around their perceived parts. A complete path on which the forearm or
  /// the open hand would come within obstacle_margin_m of one (at the staging pose, on the
  /// straight approach, or at the grasp, open or preshaped) is taken only when no grasp pose has
  /// another (an approach through a tool hung in front of the chosen one pushed the hand onto
  /// that tool's handle, the hand closed on it and knocked the chosen one off the rack: 2 of 50
  /// random episodes in session 16). The joint-space transfer is not checked against them.
  std::vector<ObstacleBox> neighbours;
  /// false: such paths are never taken, and a grasp that has only those reports kIkFailed naming
  /// the neighbour, so that a caller with other tools to choose from can try them first.
  bool neighbour_contact_allowed = true;
  /// false: grasp poses whose open or preshaped hand would touch a fixture (prefer_clear_hand's)
  /// are never planned, and a grasp that has only those reports kIkFailed saying so, so that a
  /// caller with other ways to grasp (GraspToolForAction) can try those first.
  bool fixture_contact_allowed = true;
  /// GraspToolForAction only: plan each of its ways to grasp with the hand clear of the fixtures
  /// first (fixture_contact_allowed false), and only then, in the same order, the ways that had
  /// only poses touching a fixture. false: each way as GraspHandle plans it, in order.
  bool clear_hand_first = true;
  double transfer_check_step_rad = 0.05;
  std::vector<double> transfer_raise_m = {0.05, 0.15};
  double transfer_inward_m = 0.15;
  /// GraspToolForAction only: a grasp whose tool slipped out in the lift (kDropped) or whose
  /// hand closed on nothing (kEmptyHand) backs off and grasps again, the other way round along
  /// the handle, at most this many times (>= 0). The tool is not perceived again: one that slipped
  /// out stands where it stood (it rests on the ledge again); one that fell leaves the hand empty.
  int max_regrasps = 1;
  MotionOptions approach{0.4, 0.01, 0.02, 0.05, 0.3};  // each approach waypoint
  MotionOptions lift{0.4, 0.01, 0.02, 0.05, 0.1};      // each lift waypoint (hand joints never "arrive")
  IkOptions ik;  // the Cartesian solver's options (grasp, pre-grasp, approach and lift waypoints)
  /// Screening the sampled palm poses (most are out of reach) uses ik with fewer restarts and
  /// Ipopt iterations after a failed pre-solve: presolve_restarts, >= 0, and max_iterations, >= 0
  /// (0: none, the default since session 20; at 3, Ipopt reached none of the poses the pre-solve
  /// had not in 12 random episodes, which planned the same grasps 18 % faster without it).
  int screening_restarts = 3;
  int screening_ipopt_iterations = 0;
  /// When the cheap screening finds no reachable palm pose at all (handles at the edge of the
  /// workspace), screen again with this many restarts (>= 0; 0 = no second pass) and Ipopt
  /// iterations after a failed pre-solve (>= 0; 0 = none, the default since session 22: at 60,
  /// none of 202 rescues in 7 random episodes converged, at ~18 ms each, and random-50 seeds 1
  /// and 2 planned the same grasps without them), and with min_approach_cos lowered to
  /// fallback_min_approach_cos.
  int fallback_restarts = 12;
  int fallback_ipopt_iterations = 0;
  double fallback_min_approach_cos = 0.0;
  /// The second pass retries only palm poses whose first screening solve ended within this
  /// distance of the target [m], >= 0 (farther ones are out of reach: retrying them costs
  /// seconds), besides those the wider cone adds.
  double fallback_max_error_m = 0.03;
  /// Path waypoints (pre-grasp, staging, approach, lift) are solved warm-started from their
  /// neighbour with this many restarts (>= 0) and Ipopt iterations after a failed pre-solve
  /// (>= 0, 0 = none): a restart elsewhere would jump IK branches, so a waypoint that fails from
  /// its neighbour fails the path. Ipopt's rescue is kept here (unlike the fallback pass's): in
  /// random-50 seeds 1 and 2 without it, 6 of 100 episodes planned another grasp or transfer.
  int path_restarts = 1;
  int path_ipopt_iterations = 30;
  /// Called, when set, after each stage that moved the robot, with the stage's name: "staged"
  /// (joint-space transfer done), "at_grasp" (approach done, hand open), "closed", "lifted".
  /// For observers (e.g. the bench writing a picture per stage); must not move the robot.
  std::function<void(const char* stage)> on_stage;
  /// Asked, when set, about the complete path GraspHandle chose, before anything moves: the palm
  /// pose at the grasp X_RP (in R) and the posture at the end of the lift (model q). An empty
  /// answer accepts it; any other is the reason it is refused, and GraspHandle then returns
  /// kRejected with that reason, the robot unmoved (GraspToolForAction goes on to its next way
  /// of grasping). For a caller that can tell whether the tool, held that way, can do its job
  /// (the episode: whether the pull can be planned). Must not move the robot.
  std::function<std::string(const Eigen::Isometry3d& X_RP, const Eigen::VectorXd& q_lifted)> accept_plan;
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
  kDropped,        // the fingers closed on the handle, then all the way during the lift: it slipped out
  kRejected,       // a complete path was planned, but GraspOptions::accept_plan refused it (nothing moved)
};

/// Human-readable name of a status ("grasped", "unreachable", ...).
const char* ToString(GraspStatus status);

/// Whether a grasp failed in planning, before anything moved (kUnreachable, kIkFailed or kRejected).
bool PlanningFailed(GraspStatus status);

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
  int paths_blocked = 0;        // complete paths rejected: the transfer would hit an obstacle
  std::string last_blocked;     // the last of those: which link, which obstacle, where
  bool transfer_raised = false; // the chosen transfer goes through via postures (palm raised, or joint by joint)
  /// How the chosen transfer avoids the fixtures: "direct" (no via posture), "raised" (the palm
  /// raised at either end), "arm_first" (the arm bent up, then the torso), "torso_last", "home"
  /// (through the home posture, then as a transfer from home would go).
  std::string transfer_route = "direct";
  int candidates_touching = 0;  // reachable grasp poses put last: the hand would touch a fixture there
  std::string last_touching;    // the last of those: which link, which obstacle
  bool hand_touches_fixture = false;  // the chosen pose is one of those (no other had a path)
  /// kIkFailed because such poses were the only reachable ones left and
  /// GraspOptions::fixture_contact_allowed was false (nothing moved).
  bool fixture_contact_refused = false;
  double hand_touch_depth_m = 0.0;    // then: how far its open or preshaped hand reaches into the fixture [m]
  int candidates_touching_neighbour = 0;  // complete paths on which the hand would touch a neighbour
  std::string last_neighbour_touch;       // the last of those: which link, which neighbour
  bool hand_touches_neighbour = false;    // the chosen path is one of those (no other was complete)
  int regrasps = 0;             // GraspToolForAction: grasps tried again after a slip (max_regrasps)
  std::string regrasp_reason;   // the slip that made it try again (status: reason)
  double transfer_s = 0.0;      // robot time: to the pre-grasp [s]
  double approach_s = 0.0;      // robot time: pre-grasp -> grasp [s]
  double close_s = 0.0;         // robot time: preshape, close, settle [s]
  double lift_s = 0.0;          // robot time: lift and hold [s]
};

/// Grasps a handle and lifts it with the right hand (torso + right arm chain to the palm frame):
///  1. samples palm poses P that put the hand's grasp cylinder (desc.grasp: centre and axis in P)
///     on the handle axis: both axis directions times rotations about the handle every
///     roll_step_rad, at grasp centres slid along the handle (handle_slide, centre first);
///     drops those whose approach direction fails the filters, screens the rest with a cheap IK
///     (CartesianSolver, rest posture desc.HomeQ(), warm start = the current encoders);
///  2. for the first slide offset that has any, takes the reachable poses by increasing IK rest
///     cost and plans the path: pre-grasp (pregrasp_back_m behind along -z_P, pregrasp_up_m
///     above), staging pose (further back and up), straight-line IK waypoints staging ->
///     pre-grasp -> grasp and the lift: up and back toward the robot (lift_retreat_m; straight up
///     when that is out of reach), at least lift_m and up to lift_max_m, each solve warm-started
///     from the previous posture (path_restarts, path_ipopt_iterations). The first
///     complete path wins; nothing moves before one is found;
///     With options.obstacles, a path whose transfer would bring the forearm or the open hand
///     near one is rerouted through a raised palm pose or rejected (ArmClearance), and grasp
///     poses at which the open or preshaped hand would touch one are planned last
///     (prefer_clear_hand); paths on which the hand would touch options.neighbours come after
///     all of those, or never (neighbour_contact_allowed);
///  3. opens the hand and moves (MoveJoints, joint space) to the staging pose, follows the
///     waypoints to the grasp, preshapes the hand, ramps it to desc.hand_closed over close_time,
///     checks the fingers stopped on something, lifts along the waypoints and holds hold_time.
/// The hold is by contact forces only. `X_RH` is the handle frame in R: origin at the handle
/// centre, z along the handle axis (its sign does not matter). Planning takes ~0.2-1.5 s of wall
/// time (most of it IK screening of palm poses at the edge of the workspace).
/// Throws std::invalid_argument for bad options, a non-finite X_RH or one whose rotation part is
/// not a rotation, and when desc has no right-arm chain or robot lacks a joint of desc's hand.
GraspResult GraspHandle(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Isometry3d& X_RH,
                        const GraspOptions& options = {});


/// The handle frame X_RH (z along the handle axis, either sign) turned by pi about x_H when needed
/// so that z_H points toward p_R_effector (the tool's effector centre, in R). With it, a grasp
/// with GraspOptions::axis_direction = +1 puts the effector on the +y_P side of the hand, where the
/// wrist can point the tool forward and down for a tool action (pull-gt: 5 of 5 tools grasped that
/// way pulled the ball into reach, 1 of 26 grasped the other way round). Throws
/// std::invalid_argument for a non-finite input.
Eigen::Isometry3d HandleTowardEffector(const Eigen::Isometry3d& X_RH, const Eigen::Vector3d& p_R_effector);

/// Grasps a tool by its handle to use it (PullObject), as pull-gt measured best: with the
/// effector on the +y_P side of the hand (HandleTowardEffector, axis_direction +1) first, then
/// either way round; for each, choked toward the handle's end away from the effector by 60 %,
/// 30 % and 0 % of `slide`'s extent on that side (the tool then reaches further past the hand).
/// When none of those plans, the whole handle: GraspHandle sliding anywhere in `slide` (along z of
/// the given X_RH). With options.clear_hand_first (the default) all of those ways are planned with
/// the hand clear of the fixtures first, and only then, in the same order, the ways whose only
/// reachable poses put the hand against one: the 60 % choke of a handle's lower end may be
/// reachable only with the fingertips on the rack's ledge, and closing there pushed the handle up
/// and out of the fingers. Random seeds 1-8 (400 episodes): own grasps 349 -> 359, pulls
/// 363 -> 375; but a grip less choked more often leaves no plan of the pull (re-grips 49 -> 69;
/// pull-gt, which never re-grips: 30 -> 22 of 32 tools pulled into reach). Planning only the
/// 60 % and 30 % chokes (effector on +y_P) clear first kept pull-gt at 29 but rescued none of
/// three tools that had fallen.
/// A handle lying across the rack (within 20 deg of horizontal: rot3) is grasped the whole-handle
/// way first: it rests on the ledge against the board, where the choked grasps closed on nothing
/// or let it roll out of the fingertips (table53 --episodes --seed 1, rot3: 1 of 32 grasped before,
/// choked first from a gaze solved from the current posture; 22 of 32 whole-handle first from
/// LookAt's fixed gaze seed), at the price of a grip that
/// more often leaves no plan of the action (17 of those 22 episodes then asked for a re-grip).
/// A grasp that found no plan has not moved the robot, so each next one starts from the same
/// posture; one whose transfer to the pre-grasp was blocked (kMotionTimeout: the open hand caught
/// on a neighbouring tool, which the plan does not model) moves back to that posture first, with
/// the hand open, and so does one that let the tool slip out or closed on nothing (at most
/// options.max_regrasps times; the rest of that way round is skipped). Returns the first grasp
/// that planned (its status says whether it held), else the last failure; one returned that moved
/// and does not hold has moved back too, the hand open, out of the way of another look at the
/// rack. `candidates`, plan_ms and paths_blocked are summed over all attempts, and slide_m is
/// along z of the given X_RH (e.g. app's GripSlide); options.handle_slide and
/// options.axis_direction are overridden.
/// Throws as GraspHandle and HandleTowardEffector do, and std::invalid_argument for a `slide`
/// that does not hold 0 or is not finite.
GraspResult GraspToolForAction(RobotInterface& robot, const robot::RobotDescription& desc,
                               const Eigen::Isometry3d& X_RH, const Eigen::Vector3d& p_R_effector,
                               const HandleSlide& slide, const GraspOptions& options = {});

/// What a tool action does to an object lying on the table (the thesis's pull, and the drag and
/// push actions of the tool-affordances experiments).
enum class ToolAction {
  kPull,       // toward the robot's vertical axis (z_R)
  kDragLeft,   // across, to the robot's left (-y_R side)
  kDragRight,  // across, to the robot's right (+y_R side)
  kPush,       // away from the robot's vertical axis
};

/// Name of an action: "pull", "drag-left", "drag-right", "push".
const char* ToString(ToolAction action);

/// The action named `name` (as ToString writes it, case-sensitive), or nullopt for any other name.
std::optional<ToolAction> ParseToolAction(std::string_view name);

/// Unit horizontal direction in R (z component 0) in which `action` moves an object at p_RO (in
/// R) [1]: pull = from the object toward the robot's vertical axis z_R, push = the opposite,
/// drag-left/right = perpendicular to those, to the robot's left/right. In the iCub root frame
/// (x backward, z up, hence y to the robot's right) drag-right is z_R x pull (toward +y_R for an
/// object in front of the robot) and drag-left its opposite (toward -y_R).
/// Throws std::invalid_argument for a non-finite p_RO or one on the z_R axis (closer than 1 mm
/// horizontally), where no direction is defined.
Eigen::Vector3d ActionDirection(ToolAction action, const Eigen::Vector3d& p_RO);

/// The working part of a tool held in the hand, in the tool frame T (toollib's effector segment).
struct ToolEffector {
  /// Effector centre p_TE in T [m]; finite.
  Eigen::Vector3d center_T = Eigen::Vector3d::Constant(std::nan(""));
  /// Working direction in T (the side that meets the object when pulling; +x_T for library
  /// tools); finite and non-zero (normalised by the skill).
  Eigen::Vector3d direction_T = Eigen::Vector3d::UnitX();
  double half_thickness_m = 0.005;  // effector half-size along the working direction [m], >= 0
  /// Surface points of the effector region in T [m], 3xN (e.g. the mesh vertices near center_T);
  /// optional. When given (with tool_points_T), PullObject places the start for each sampled tool
  /// orientation from the geometry instead of half_thickness_m: the effector as close behind the
  /// object as clearance_m allows, lifted so that no tool point is below the object's support.
  Eigen::Matrix3Xd points_T;
  /// Surface points of the whole held tool in T [m], 3xN (e.g. its mesh vertices); optional,
  /// used with points_T: orientations whose tool (shaft included) would come down on the object
  /// during the descent to the start are rejected.
  Eigen::Matrix3Xd tool_points_T;
};

/// Options of PullObject. Defaults pull the scene's ball (scenes/default.json) with library tools
/// grasped from the rack (measured by `toolbench bench --protocol pull-gt`).
struct PullOptions {
  /// What the skill does to the object: the drag direction is ActionDirection(action, p_RO) (turned
  /// by up to max_pull_turn_rad), and the effector starts on the object's far side from it.
  ToolAction action = ToolAction::kPull;
  double clearance_m = 0.01;        // gap between the object's far surface and the effector [m], >= 0
  /// With effector points (ToolEffector::points_T): lowest tool point this far above the object's
  /// support plane (object centre height minus its radius) at the start [m], >= 0; the effector is
  /// moved behind the object in steps of start_step_m [m] (> 0), its centre at most
  /// max_start_distance_m [m] (> 0) from the object centre (horizontally).
  double support_clearance_m = 0.008;
  double start_step_m = 0.005;
  double max_start_distance_m = 0.16;
  /// Lowest palm origin height above the object's support plane at the start [m] (the hand wraps
  /// about 4 cm around the handle; lower palms drive it into the table), >= 0.
  double min_palm_height_m = 0.05;
  /// A start pose whose IK ends up to this far from the target [m] (>= 0; 0 = exact) is accepted
  /// when the tool where the palm really ends is still clear of the object and behind it; the
  /// descent and drag are then planned from there (the edge of the workspace).
  double start_tolerance_m = 0.012;
  /// The left arm is fixed to the torso: a torso leaning toward the table drives it into the
  /// table, and the torso then cannot reach the planned posture. Postures (start, descent, drag)
  /// that put a link of left_arm_links lower than this above the object's support are
  /// rejected [m], >= 0.
  double left_arm_clearance_m = 0.06;
  std::vector<std::string> left_arm_links{"l_hand", "l_wrist_1", "l_forearm"};
  double height_offset_m = 0.0;     // effector centre height above the object centre [m]
  double pull_length_m = 0.25;      // planned drag along the action's direction [m], > 0
  /// The object's support (the table top) as a box in the horizontal plane of R [m]; empty (the
  /// default) = unbounded. The drag along each direction (max_pull_turn_rad) is cut so that the
  /// object, moved support_travel_fraction (in (0, 1]) of the drag along it, keeps its centre
  /// object_radius + support_edge_margin_m [m] (>= 0) inside the box (an object that starts nearer
  /// an edge may come 2 cm closer to it); a direction left with less than min_pull_fraction of
  /// pull_length_m is not tried. A drag turned toward the rack pushed the ball off the table's
  /// side (random 50, seed 1, episode 13). The ball moves half the drag in the median, but a flat
  /// effector square to the drag launches it: it rolls on after the drag has stopped (random
  /// seeds 1-4, per planned metre of drag: hoes 1.09 m in the median, rakes 0.66 m and 2.5 m at
  /// the 90th percentile). Cut for half the drag (0.5), turned drags rolled 7 balls off the
  /// table's side; cut for all of it (1), which shortens the turned ones, pulls into reach
  /// 171 -> 177 of 200, none lost (in the first 150 episodes: 0.75 pulled 129, 1 with 10 cm more
  /// kept for the ball's roll 126, 1 alone 130). pull-gt, seeds 1-3: 85 of 96 against 86.
  Eigen::AlignedBox2d support_xy;
  double support_edge_margin_m = 0.05;
  double support_travel_fraction = 1.0;
  /// The drag may be cut short where IK stops converging, but not below this fraction of
  /// pull_length_m, in (0, 1].
  double min_pull_fraction = 0.3;
  /// Orientations are planned lowest rest cost first; the first complete plan with the whole
  /// drag wins, else the one with the longest drag among the first max_complete_plans (> 0)
  /// complete plans (the first one only: 1).
  int max_complete_plans = 4;
  double approach_height_m = 0.10;  // the effector comes down from this far above the start [m], >= 0
  /// Tool orientations sampled: elevation of the palm -> effector line below the horizontal
  /// (min..max, step) [rad]; yaw of that line about z_R either side of the pull line [rad];
  /// roll of the tool about that line either side of "working side faces the robot" [rad].
  /// Low elevations reach furthest (a nearly horizontal tool), high ones lift the shaft over the
  /// object; the lowest rest cost decides among those that plan.
  double min_elevation_rad = 5.0 * M_PI / 180.0;
  double max_elevation_rad = 50.0 * M_PI / 180.0;
  double elevation_step_rad = 9.0 * M_PI / 180.0;
  double max_yaw_rad = 60.0 * M_PI / 180.0;
  double yaw_step_rad = 20.0 * M_PI / 180.0;
  double max_roll_rad = 90.0 * M_PI / 180.0;
  double roll_step_rad = 30.0 * M_PI / 180.0;
  /// Before the joint-space transfer the hand first moves straight back toward the robot's axis
  /// (horizontally) and up by these amounts, keeping its orientation, so that the tool leaves the
  /// place it was taken from (the rack) before it swings [m], >= 0; cut short where IK ends.
  double clear_back_m = 0.15;
  double clear_up_m = 0.05;
  /// From there the hand goes to a via point carry_up_m [m] above and carry_back_m [m] back
  /// toward the robot from the pose above the start, turning the tool to its working orientation
  /// on the way (position on a line, orientation slerped, transfer_waypoints IK waypoints, >= 2),
  /// then straight down to above the start (no turning near the table). Every transfer waypoint
  /// must keep each tool point (ToolEffector::tool_points_T, when given) above the object's
  /// support and object_clearance_m [m] away from the object, and the fixed left arm's links
  /// left_arm_clearance_m above the object's top when within left_arm_object_radius_m [m] of it
  /// horizontally (a turning torso sweeps the left arm across the table). Consecutive postures may
  /// differ by at most max_joint_step_rad [rad] in every joint (more means IK changed branch and
  /// the arm would swing between them); a larger step is halved up to three times. Lower via
  /// points (half, then none) are tried when a path does not plan. All >= 0 except
  /// max_joint_step_rad > 0.
  double carry_up_m = 0.12;
  double carry_back_m = 0.08;
  int transfer_waypoints = 10;
  double object_clearance_m = 0.03;
  double left_arm_object_radius_m = 0.15;
  /// Fixed boxes of the workspace other than the object's support (the rack: from the scene file,
  /// not perceived) that every tool point must keep fixture_clearance_m [m] (>= 0) clear of on the
  /// transfer's turn and descent (with tool_points_T). A box the tool is already nearer than that
  /// where the turn starts (just off the rack) must not be approached any further. Empty = no
  /// check: a long hook turned near the rack swung its far end into the board and left the hand
  /// (random-50 seeds 1-4: pulls 178 without the check, 180 with it; none lost).
  std::vector<ObstacleBox> fixtures;
  double fixture_clearance_m = 0.02;
  double max_joint_step_rad = 0.3;
  /// The drag direction may turn about z_R away from the action's direction (ActionDirection) by
  /// up to this much, either way, in steps of pull_turn_step_rad [rad], in [0, pi/2] (the first
  /// that plans wins, straight first; for a pull, the start then lies nearer a shoulder).
  /// pull-gt: 30 deg 20/32 into reach, 60 deg 25/32, 90 deg 25/32 (a drag turned 60 deg still
  /// moves the ball half its length toward the robot).
  double max_pull_turn_rad = 60.0 * M_PI / 180.0;
  double pull_turn_step_rad = 15.0 * M_PI / 180.0;  // > 0
  int descend_waypoints = 3;  // IK waypoints of the straight descent to the start, >= 1
  int drag_waypoints = 10;    // IK waypoints of the drag, >= 2
  /// Consecutive drag postures may differ by at most this much in any joint [rad], > 0; a larger
  /// step is halved up to twice, and the drag ends before a step that stays larger (IK changed
  /// branch: the wrist flipped the tool over, next to the object, and flung it off the table).
  /// Wider than max_joint_step_rad: a drag moves slowly against the object, where steps of up to
  /// 0.45 rad are common and harmless (0.3 without halving halved pull-gt's successes).
  double max_drag_joint_step_rad = 0.6;
  int lift_waypoints = 4;     // IK waypoints of the lift after the drag, >= 1
  /// The lift rises approach_height_m and goes this far back along the drag [m], >= 0 (away from
  /// the object: the drag ends with the arm folded near the body, where a lift straight up was
  /// often out of reach and left the tool on the table).
  double lift_back_m = 0.05;
  /// The lift stays near the drag's last posture and may tilt the palm by up to this much [rad],
  /// >= ik.orientation_tolerance_rad: the drag often ends at the edge of the workspace, where a
  /// lift at a fixed orientation was cut short and left the tool on the table.
  double lift_orientation_tolerance_rad = 0.5;
  MotionOptions transfer{3.0, 0.01, 0.02, 0.05, 0.5};  // the transfer to above the start: duration shared by its waypoints
  MotionOptions waypoint{0.3, 0.01, 0.02, 0.05, 0.1};  // each descent / lift waypoint
  /// Each drag waypoint (duration per waypoint, streamed). At an even pace: a minimum-jerk drag
  /// peaks at 1.9x its mean speed halfway, where it starts to slow down, and the ball it pushed
  /// rolls on ahead of it, along the effector's face, often off the table's side (7 of 100
  /// random episodes, seeds 1 and 2); cruising at 1.33x the mean between short ramps (blend
  /// 0.25) keeps the ball against the effector: pull 84 -> 91 and ball grasp 80 -> 84 of 100.
  /// 0.45 s a waypoint (0.3 until session 50: a 25 cm drag cruising at 7.4 cm/s, not 11): the
  /// ball leaves the drag slower and rolls on less (random seeds 1-6: p90 of its travel in the
  /// lift after the drag 5.3 -> 3.0 cm); pull 268 -> 273 and ball grasp 256 -> 260 of 300 with the
  /// session-49 affordance model (held-out seeds 5 and 6: 86 -> 91 pulls; 0.6 s: 275 pulls, 257
  /// balls, at twice the added robot time).
  MotionOptions drag{0.45, 0.01, 0.02, 0.05, 0.1, 0.0, 0.3, 0.25};
  /// Finger joints closer than this to hand_closed after the drag mean the tool was lost [rad], > 0.
  double empty_hand_tol = 0.05;
  double arm_arrival_tol = 0.08;  // largest arm joint error accepted above the start [rad], > 0
  /// Above the start, its offsets then kept through the descent, drag and lift. The servos sag
  /// under a long tool's weight: a stick's effector came down 1.5 cm below the plan (random
  /// episode 13), its shaft onto the ball.
  SagCompensation sag;
  /// Waypoint solves. Without Ipopt after a failed pre-solve: planning a pull tries hundreds of
  /// poses, most of them out of reach, and Ipopt's rescue (rarely successful, ~0.6 ms an
  /// iteration) made the plan ~9x slower (benchmarks/control_benchmark.cpp BM_PlanPull: 8.6 s ->
  /// 0.93 s with the screening's; pull-gt's success unchanged, see the session-5 note).
  IkOptions ik = [] {
    IkOptions o;
    o.ipopt_after_failed_presolve = false;
    return o;
  }();
  int screening_restarts = 3;     // cheap IK for sampled orientations: restarts, >= 0
  /// And Ipopt iterations after a failed pre-solve, >= 0 (0: none, the default; 10 until session 5).
  int screening_ipopt_iterations = 0;
  /// Restarts (>= 0) of the path waypoints' solves (transfer, descent, drag), each warm-started
  /// from its neighbour: a restart elsewhere lands on another IK branch, which the path refuses
  /// (max_joint_step_rad), so a waypoint that fails from its neighbour fails anyway. With
  /// ik.presolve_restarts (30) these failing waypoints were most of a plan's cost.
  int path_restarts = 1;
  /// Called, when set, after each stage that moved the robot, with the stage's name:
  /// "above_start" (transfer done), "at_start" (descent done),
  /// "dragged", "lifted". For observers; must not move the robot.
  std::function<void(const char* stage)> on_stage;
  void Validate() const;  // throws std::invalid_argument naming the field and its value
};

/// How a pull ended.
enum class PullStatus {
  kPulled,         // the effector went behind the object and was dragged toward the robot
  kUnreachable,    // no sampled tool orientation puts the effector behind the object within reach
  kIkFailed,       // a start pose was reachable but the approach or the drag was not
  kMotionTimeout,  // the arm did not arrive above the start
  kLostTool,       // the fingers closed all the way: the tool left the hand
};

/// Human-readable name of a status ("pulled", "unreachable", ...).
const char* ToString(PullStatus status);

/// Whether an action failed in planning, before anything moved (kUnreachable or kIkFailed).
bool PlanningFailed(PullStatus status);

/// Outcome of PullObject.
struct PullResult {
  PullStatus status = PullStatus::kUnreachable;
  std::string reason;                                      // empty when pulled
  ToolAction action = ToolAction::kPull;                   // the action performed (PullOptions::action)
  Eigen::Isometry3d X_RT_start = Eigen::Isometry3d::Identity();  // planned tool pose at the drag start, in R
  Eigen::Vector3d pull_dir_R = Eigen::Vector3d::Zero();    // unit horizontal drag direction used, in R
  double pull_turn_rad = 0.0;    // its turn about z_R from ActionDirection(action, p_RO) [rad]
  /// Cosine between the working side's horizontal direction at the start and pull_dir_R (for a
  /// flat side, the ball it pushes tends to roll along it when this is small).
  double working_cos = 0.0;
  double planned_drag_m = 0.0;   // length of the planned drag [m]
  double planned_lift_m = 0.0;   // height of the planned lift after it [m] (approach_height_m when complete)
  double elevation_rad = 0.0;    // chosen orientation sample (see PullOptions)
  double yaw_rad = 0.0;
  double roll_rad = 0.0;
  int candidates = 0;            // orientations sampled
  int candidates_feasible = 0;   // with a converged start-pose IK
  int candidates_blocked = 0;    // with no collision-free start behind the object, or the palm too low
  double start_distance_m = 0.0; // horizontal distance object centre -> effector centre at the start [m]
  double plan_ms = 0.0;          // wall time of planning [ms], informational
  double motion_s = 0.0;         // robot time of the whole motion [s]
  /// Largest servo-sag offset carried into the descent and drag [rad] (PullOptions::sag),
  /// and the palm's distance (encoders) from the planned start when the descent ends [m] (NaN
  /// when the arm never got there).
  double sag_offset_rad = 0.0;
  double start_palm_error_m = std::nan("");
};

/// A planned tool action (PlanPull): the result so far and the right-arm chain postures (model q,
/// URDF order) to execute. result.status is kPulled when the plan is complete (nothing moved yet),
/// else kUnreachable or kIkFailed with the reason; the postures are then empty.
struct PullPlan {
  PullResult result;
  /// Cartesian transfer from q_model: back and up off the rack, to the via point turning the tool,
  /// down to above the start (PullOptions::carry_up_m); the last posture is q_above.
  std::vector<Eigen::VectorXd> transfer;
  Eigen::VectorXd q_above;                // above the start (the transfer ends here)
  std::vector<Eigen::VectorXd> descend;   // straight descent to the start (last = the start)
  std::vector<Eigen::VectorXd> drag;      // the drag along result.pull_dir_R
  std::vector<Eigen::VectorXd> lift;      // the lift after the drag (may be shorter than asked)
  bool complete() const { return result.status == PullStatus::kPulled; }
};

/// Plans PullObject's motion from the posture q_model (model q, URDF order; e.g. the encoders)
/// without moving anything: steps 1-2 of PullObject. Same arguments and exceptions as PullObject
/// (less the robot).
PullPlan PlanPull(const robot::RobotDescription& desc, const Eigen::VectorXd& q_model, const Eigen::Isometry3d& X_PT,
                  const ToolEffector& effector, const Eigen::Vector3d& p_RO, double object_radius,
                  const PullOptions& options = {});

/// Pulls an object (a ball) toward the robot with a tool held in the right hand, or drags it
/// sideways or pushes it away (PullOptions::action):
///  1. the drag direction u is ActionDirection(options.action, p_RO), horizontal (or turned by up
///     to max_pull_turn_rad, straight first); the start puts the effector centre beyond the
///     object on the line through it along -u (the object's far side from u). With effector points (ToolEffector::points_T, tool_points_T) the
///     start is found per sampled orientation: the tool at the object's centre height (+
///     height_offset_m), raised until its lowest point is support_clearance_m above the object's
///     support, moved out along -u from the object until no tool point would come down on the
///     object (inflated by clearance_m) during the vertical descent; rejected when then no effector
///     point lies beyond the object within its cross-section, or the palm is lower than
///     min_palm_height_m above the support. Without points: (object_radius + clearance_m +
///     effector.half_thickness_m) from its centre along -u, at its centre height (+ height_offset_m);
///  2. samples tool orientations: the palm -> effector line points away from the robot and down
///     (elevation, yaw about z_R from the horizontal direction from the robot's axis to the
///     object, turned as u is), the working direction as close to u as that allows (roll),
///     screens each with a cheap IK of the palm pose X_RP = X_RT * X_PT^-1, then plans, lowest
///     rest cost first: above the start (approach_height_m up), straight descent, straight drag
///     of pull_length_m along u (cut short where IK ends, not below min_pull_fraction), lift;
///     The planned path includes the transfer from the current posture (PullPlan::transfer: back
///     and up off the rack, the tool turned high above the table, straight down to above the
///     start; continuity and clearance rules at PullOptions::carry_up_m); an orientation whose
///     transfer does not plan is skipped;
///  3. moves along it keeping the hand closed, and checks from the finger encoders that the tool
///     is still in the hand.
/// `X_PT` is the tool in the palm frame as the grasp left it (handle pose times the planned palm
/// pose: GraspResult::X_RP_grasp.inverse() * X_RH * X_TH.inverse()); `p_RO` the object centre in R.
/// Never throws for an unreachable object (a status). Throws std::invalid_argument for bad
/// options, a non-finite p_RO, X_PT or effector (a tool without effector information), a
/// non-positive object_radius, effector points given without tool points (or the reverse), or a
/// robot without the hand joints.
PullResult PullObject(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Isometry3d& X_PT,
                      const ToolEffector& effector, const Eigen::Vector3d& p_RO, double object_radius,
                      const PullOptions& options = {});

/// Options of MovePalmThrough.
struct PalmPathOptions {
  double step_m = 0.08;             // IK waypoint spacing along each segment [m], > 0
  double max_joint_step_rad = 0.3;  // largest joint change between waypoints (else IK changed branch) [rad], > 0
  MotionOptions waypoint{0.25, 0.01, 0.02, 0.05, 0.5};  // per waypoint, streamed (MoveThrough)
  /// Waypoint solves keep the palm's current orientation loosely (orientation_length_m small:
  /// position first) and rest at the current posture.
  IkOptions ik = [] {
    IkOptions o;
    o.orientation_tolerance_rad = 1.0;
    o.orientation_length_m = 0.02;
    return o;
  }();
  void Validate() const;  // throws std::invalid_argument naming the field
};

/// Outcome of MovePalmThrough.
struct PalmPathResult {
  bool complete = false;    // every point planned and the arm arrived at the last one
  int points_reached = 0;   // points whose segment planned in full
  std::string reason;       // why not complete
  MotionResult motion;      // of the streamed path
};

/// Moves the palm along straight segments from where it is through `points_R` [m, in R], its
/// orientation held loosely, each IK posture near the last (no branch jumps). Plans first and
/// moves along the part that planned; a point that does not plan ends the path there (reported,
/// not thrown). For clearing the hand of a surface before a joint-space move. Throws
/// std::invalid_argument for bad options or non-finite points.
PalmPathResult MovePalmThrough(RobotInterface& robot, const robot::RobotDescription& desc,
                               const std::vector<Eigen::Vector3d>& points_R, const PalmPathOptions& options = {});

/// Options of PutDown.
struct PutDownOptions {
  double release_height_m = 0.03;  // lowest tool point this far above the surface when the hand opens [m], >= 0
  double retreat_up_m = 0.10;      // the open hand rises this far afterwards [m], >= 0
  /// Before the transfer the palm rises straight up until it is this far above the surface [m],
  /// >= 0: a joint-space transfer from low over the table swept the held tool across it (and the
  /// ball off it, in 7 of 50 random episodes).
  double clear_height_m = 0.2;
  PalmPathOptions clear;           // that rise
  /// The tool's points in T (e.g. its mesh vertices); empty: the checks below are off. Where the
  /// hand opens, no tool point may lie within keep_out_radius_m [m] (horizontally) of a centre in
  /// keep_out_R [m, in R] (e.g. the ball: a long tool laid over it knocked it off the table), and
  /// the points' centroid (about the centre of mass) must lie in support_xy when that is not
  /// empty (the surface in R's x-y, less a margin), so that the tool stays on the surface. On the
  /// way there (the rise, the crossing, the joint-space turn sampled every 0.05 rad and the
  /// descent), no tool point lower than keep_out_radius_m above a centre may come within
  /// keep_out_radius_m of it horizontally (every 8th point is checked).
  Eigen::Matrix3Xd tool_points_T;
  /// The tool's main axis in T (e.g. its handle axis; finite): when not zero it, not the hand's
  /// grasp axis, is laid level. A handle held across the grasp axis at 16-18 deg left long tools
  /// tilted over the table, one end down, and they tumbled when the hand opened (shovel_3 into the
  /// ball in episode 10 of random-50, seed 1).
  Eigen::Vector3d tool_axis_T = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3d> keep_out_R;
  double keep_out_radius_m = 0.08;
  Eigen::AlignedBox2d support_xy;
  /// Not speed-limited (MotionOptions::max_speed): it carries the tool near the table and the
  /// ball. Sped up to 1.5 rad/s together with the looks made holding a tool, 3 of 50 random
  /// episodes lost the ball off the table (those 3 in the look; this transfer was not isolated).
  MotionOptions transfer{2.0, 0.01, 0.02, 0.05, 2.0};
  MotionOptions open{0.5, 0.01, 0.02, 0.05, 0.0};
  double settle_time = 0.5;        // wait after opening [s], >= 0
  /// Palm yaws and places out of reach are common: no Ipopt rescue after a failed pre-solve (as
  /// PullOptions::ik).
  IkOptions ik = [] {
    IkOptions o;
    o.ipopt_after_failed_presolve = false;
    return o;
  }();
  void Validate() const;
};

/// Outcome of PutDown.
struct PutDownResult {
  bool placed = false;           // the hand reached the place and opened
  std::string reason;            // why not, when not placed
  Eigen::Isometry3d X_RP = Eigen::Isometry3d::Identity();  // palm pose where the hand opened
  int poses_sampled = 0;         // palm poses tried: 12 yaws, x 4 rolls about the handle with tool points
  int yaws_off_surface = 0;      // palm poses rejected: the tool's centroid off PutDownOptions::support_xy
  int yaws_kept_out = 0;         // palm poses rejected: a tool point near a keep-out centre
  int paths_kept_out = 0;        // palm poses rejected: the way there brings a tool point near one
  /// The open hand's straight rise was cut short (IK from where the hand really is, at its
  /// orientation there): it went back up the way it came down instead, to 10 cm above the
  /// release pose. Without that it stayed beside the tool it had let go of, and the next move
  /// dragged the hand across the tool (random-50 seed 2: 2 of 5 failed ball grasps).
  bool rise_retraced = false;
  std::string rise_reason;       // then: why the rise was cut short
};

/// Puts a held tool down: moves the palm so that the tool hangs above `p_R_place` (a free spot on
/// a horizontal surface at height p_R_place.z(), in R) with the tool's handle horizontal, lowered
/// until its lowest point (tool_radius_m below the handle axis) is release_height_m above the
/// surface, opens the hand, waits, and lifts the open hand. Tries palm yaws about z_R (and, with
/// PutDownOptions::tool_points_T, rolls about the handle, the tool's lowest point then
/// release_height_m above the surface) until IK converges; when none does, nothing has moved
/// (placed = false, with the reason). Throws
/// std::invalid_argument for bad options or non-finite input.
PutDownResult PutDown(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Isometry3d& X_PT,
                      const Eigen::Vector3d& p_R_place, double tool_radius_m, const PutDownOptions& options = {});

/// Options of GraspBall.
struct BallGraspOptions {
  double lift_m = 0.08;            // lift after closing [m], >= 0
  double pregrasp_up_m = 0.08;     // the palm comes down from this far above the grasp [m], >= 0
  /// Gap between the palm and the ball's surface along the palm normal [m], >= 0 (the fingers
  /// wrap around the ball from there).
  double palm_gap_m = 0.01;
  double roll_step_rad = 30.0 * M_PI / 180.0;  // palm rotations sampled about its normal, in (0, pi]
  /// Tilts of the palm normal from straight down toward "from the robot side" tried in turn
  /// (0 = top grasp, larger = side grasp) [rad], each in [0, pi/2].
  std::vector<double> tilts_rad{0.0, 0.5, 1.0};
  /// The hand crosses to the ball at least this high above the ball's top [m], > 0: from where it
  /// is, straight up to that height (when lower), a joint-space move to above the pre-grasp during
  /// which the palm stays that high (less half of it) while within radius + this of the ball
  /// horizontally (twice as high when the move dips more, half as high when the higher poses are
  /// out of reach), then straight down to the pre-grasp.
  /// A direct joint-space move from the put-down swept the hand through the ball in 5 of 50
  /// random episodes, knocking it off the table.
  double clear_height_m = 0.12;
  /// Fixtures the arm (forearm and open hand, ArmClearance) keeps obstacle_margin_m [m] (>= 0)
  /// clear of on that joint-space crossing; when it would not, the palm crosses on a straight
  /// line (orientation slerped) instead, which must keep clear too. From a put-down beside the
  /// rack, the joint-space crossing caught the hand on the rack's ledge and the pre-grasp was not
  /// reached (2 of 100 random episodes, seeds 1 and 2). Empty = no check.
  std::vector<ObstacleBox> obstacles;
  double obstacle_margin_m = 0.0;
  MotionOptions transfer{2.0, 0.01, 0.02, 0.05, 2.0, kTransferSpeed};
  MotionOptions waypoint{0.4, 0.01, 0.02, 0.05, 0.1};  // each approach and lift waypoint
  /// Each waypoint of the straight rise to the crossing height and of the descent to the
  /// pre-grasp: the empty hand in free space, at the transfers' peak joint speed (at the
  /// approach's fixed 0.4 s a waypoint, the rise from a put-down took 1.2 s for 0.13 rad).
  MotionOptions clear_line{0.4, 0.01, 0.02, 0.05, 0.1, kTransferSpeed};
  double close_time = 0.8;         // [s], > 0
  double hold_time = 0.5;          // [s], >= 0
  double empty_hand_tol = 0.05;    // [rad], > 0
  IkOptions ik;
  /// GraspBall solves its palm poses, pre-grasps and crossings with ik, but with this many Ipopt
  /// iterations after a failed pre-solve (>= 0; 0 = none, the default since session 22: at 200,
  /// none of 45 rescues in 8 random episodes converged, at ~58 ms each; BallInReach keeps its
  /// rescue of near misses, reach_rescue_max_error_m).
  int grasp_ipopt_iterations = 0;
  /// BallInReach: every palm pose is first solved by the pre-solve alone; Ipopt's rescue runs only
  /// for those that ended within this distance of it [m], >= 0 (infinity: for every pose, as
  /// before). A ball out of reach cost ~0.44 s of rescues over 36 poses, none of which converged.
  double reach_rescue_max_error_m = 0.03;
  /// Called, when set, after each stage that moved the robot: "pre_grasp", "at_grasp", "closed",
  /// "lifted". For observers; must not move the robot.
  std::function<void(const char* stage)> on_stage;
  void Validate() const;
};

/// Whether a palm pose to grasp a ball at p_RB (radius, in R) from above has a converged IK: the
/// bench's definition of "the ball is within reach". Throws on non-finite input.
bool BallInReach(const robot::RobotDescription& desc, const Eigen::VectorXd& q_model, const Eigen::Vector3d& p_RB,
                 double radius, const BallGraspOptions& options = {});

/// Whether the ball at p_RB would still be in reach (BallInReach) margin_m [m] (>= 0) farther
/// from the robot's vertical axis: well within reach, not at its edge, where a palm pose
/// converges but GraspBall's crossing cannot keep the hand above the ball. Throws as
/// BallInReach, and for a negative or non-finite margin.
bool BallWithinReach(const robot::RobotDescription& desc, const Eigen::VectorXd& q_model, const Eigen::Vector3d& p_RB,
                     double radius, double margin_m, const BallGraspOptions& options = {});

/// Grasps a ball lying on the table with a whole-hand top grasp: palm above the ball (normal
/// down), fingers wrapping around it, close, lift. The palm poses are tried in turn and the first
/// with a complete path is taken (candidates_feasible counts the converged grasp IKs among those
/// tried). Statuses as GraspHandle's (kGrasped means the fingers stopped on something; scoring
/// checks the lift from ground truth). Throws
/// std::invalid_argument for bad options, non-finite p_RB or a non-positive radius.
GraspResult GraspBall(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Vector3d& p_RB,
                      double radius, const BallGraspOptions& options = {});

/// Options of the hand-over fallback.
struct HandOverOptions {
  double point_distance_m = 0.30;  // the open palm goes this far from the root axis toward the tool [m], > 0
  double point_height_m = 0.10;    // at this height in R [m]
  /// Where the open palm waits for the tool instead (in R [m]), when finite: e.g. in front of the
  /// robot above the table, clear of the rack. Held out toward the rack, a long tool put in the
  /// hand overlapped the rack and the tools beside it and stuck there: the pull's transfer then
  /// did not arrive (4 of 50 random episodes). NaN (the default): point_distance_m toward the tool.
  Eigen::Vector3d receive_at_R = Eigen::Vector3d::Constant(std::nan(""));
  MotionOptions transfer{2.0, 0.01, 0.02, 0.05, 2.0, kTransferSpeed};
  MotionOptions hand{0.5, 0.01, 0.02, 0.05, 0.0};
  double wait_s = 1.0;             // the open hand waits this long for the tool [s], >= 0
  double close_time = 0.3;         // [s], > 0
  double settle_time = 0.3;        // [s], >= 0
  IkOptions ik;
  void Validate() const;
};

/// The human's part of a hand-over: places the tool in the open hand and holds it there. Called
/// by HandOver while the hand waits open, with the palm pose X_RP where the hand waits (in R),
/// and again, with the same pose, every command period while the fingers close (the person
/// holds the tool still until the hand has it, then lets go). Implemented
/// by the simulator as an explicit, recorded teleport of the tool's free joint (the only one the
/// bench permits), by a real setup as a person.
using PlaceToolInHand = std::function<void(const Eigen::Isometry3d& X_RP)>;

/// Outcome of HandOver.
struct HandOverResult {
  bool assisted = true;          // always true: the tool came from a human, not from a grasp
  bool holding = false;          // the fingers stopped on something after closing
  std::string reason;            // why not holding
  Eigen::Isometry3d X_RP = Eigen::Isometry3d::Identity();  // palm pose where the hand waited
};

/// The hand-over fallback (thesis Fig. 5.20): points the open hand toward the tool at p_R_tool
/// (palm up, at point_distance_m from the root axis in the tool's direction), waits, calls
/// `place` (the human puts the tool in the hand), closes the hand and checks the fingers stopped
/// on something. The result is flagged assisted. Throws std::invalid_argument for bad options, a
/// non-finite p_R_tool or an empty `place`.
HandOverResult HandOver(RobotInterface& robot, const robot::RobotDescription& desc, const Eigen::Vector3d& p_R_tool,
                        const PlaceToolInHand& place, const HandOverOptions& options = {});

}  // namespace toolbench::control
