#pragma once

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>

#include "app/bench.h"
#include "app/scene_setup.h"
#include "control/skills.h"

namespace toolbench::app {

/// The rack cell pull-gt puts each tool in by default.
inline constexpr const char* kPullCell = "rot0";

/// How one ground-truth pull case runs and is judged.
struct PullCaseOptions {
  std::string cell = kPullCell;     // rack cell of the tool (Table 5.3 name)
  /// Ball centre range (x, then y, in R) drawn from the case seed, replacing the scene's [m]: as
  /// in scenes/default.json, just out of the arm's reach (BallInReach is false for x <= -0.60 at
  /// every y in the range; a top grasp reaches x = -0.59), so the pull must bring it closer.
  Eigen::Vector2d ball_x_range{-0.62, -0.60};
  Eigen::Vector2d ball_y_range{-0.10, 0.05};
  double settle_after_s = 1.0;      // wait after the pull before measuring the ball [s], > 0
  double min_lift_m = 0.05;         // the grasp must lift the tool this far (grasp-gt criterion) [m], > 0
  /// After the pull: put the tool down on the table away from the ball as the episode does
  /// (PutDownOnTable, keeping out of where the ball really is: this bench isolates control) and,
  /// when the ball is in reach, grasp it (success = ball >= ball_lift_m above the table, held).
  bool put_down_and_grasp_ball = true;
  double ball_lift_m = 0.03;        // [m], > 0
  /// After the grasp, look at the tool in the hand and plan the pull with the pose seen there
  /// (InspectHeldTool); false: with the pose the grasp planned (the tool pivots in the grip as
  /// it leaves the rack, so that pose is 10-45 deg off: the baseline).
  bool inspect_held_tool = true;
  control::GraspOptions grasp;      // grasp of the handle (slides along it as grasp-gt does)
  control::PullOptions pull;
  control::PutDownOptions put_down;
  control::BallGraspOptions ball_grasp;
  void Validate() const;  // throws std::invalid_argument naming the field and its value
};

/// Outcome of one pull case.
struct PullCaseResult {
  std::string tool;
  std::string family;
  bool grasped = false;              // tool lifted >= min_lift_m (ground truth)
  control::GraspResult grasp;
  control::PullResult pull;
  Eigen::Vector3d ball_start_R = Eigen::Vector3d::Zero();  // ground truth, before the pull [m]
  Eigen::Vector3d ball_end_R = Eigen::Vector3d::Zero();    // after the pull and settle_after_s [m]
  double displacement_m = 0.0;       // ball motion along the horizontal direction toward the robot's axis [m]
  /// After the grasp's lift: distance of the effector centre (ground truth) from where the assumed
  /// in-hand pose puts it [m], and the rotation between the two [deg] (the tool pivots in the
  /// grip as it leaves the rack). NaN when not grasped.
  double lift_slip_m = std::nan("");
  double lift_pivot_deg = std::nan("");
  /// At the start of the drag (NaN when the arm never got there): distance of the effector centre
  /// (ground truth) from where the plan put it, and from where the encoders' palm pose and the
  /// assumed in-hand pose put it (the tool moved in the hand) [m].
  double start_effector_error_m = std::nan("");
  double start_slip_m = std::nan("");
  /// How far the ball moved (ground truth) while the tool was grasped, and between the grasp and
  /// the start of the drag (NaN when not reached): the arm or tool hit it [m].
  double ball_moved_by_grasp_m = std::nan("");
  double ball_moved_before_drag_m = std::nan("");
  /// The tool in the hand as the grasp left it (planned): unit direction from the palm origin to
  /// the effector centre, and the effector's working direction (+x_T), both in the palm frame P.
  Eigen::Vector3d in_hand_effector_dir_P = Eigen::Vector3d::Zero();
  Eigen::Vector3d in_hand_working_dir_P = Eigen::Vector3d::Zero();
  /// Looking at the held tool (PullCaseOptions::inspect_held_tool): whether the estimate was used,
  /// why not, and the error of the in-hand pose the pull planned with against the truth when the
  /// frame was taken: rotation [deg] and effector centre [m] (NaN when not inspected).
  bool inspected = false;
  std::string inspect_reason;
  double used_pose_error_deg = std::nan("");
  double used_effector_error_m = std::nan("");
  bool ball_in_reach_before = false; // BallInReach at the start (should be false: the ball is out of reach)
  bool ball_in_reach = false;        // BallInReach after the pull: the pull succeeded
  bool put_down = false;             // PutDown placed the tool
  bool ball_grasp_tried = false;
  bool ball_grasped = false;         // ball >= ball_lift_m above its rest height after GraspBall's hold
  std::string ball_grasp_status;     // GraspBall's status and reason, when tried
  std::string ball_grasp_reason;
  int ball_crossings_blocked = 0;    // GraspBall's joint-space crossings that would hit a fixture
  double ball_lift_m = 0.0;
  std::string reason;                // first failed stage, empty when the ball ended in reach
  double sim_time = 0.0;             // [s]
  double wall_ms = 0.0;              // [ms], informational
};

/// One case: `tool` alone in options.cell, the ball where the seed puts it (out of reach on the
/// table), grasp from the ground-truth handle (GraspToolForAction), a look at the tool in the hand
/// (InspectHeldTool; the prior is the grasp plan's X_PT = X_RP^-1 X_RH X_TH^-1), PullObject with
/// the tool's effector segment, the ball's ground-truth position as the target (this isolates
/// the pull from the rack perception), then put-down and ball grasp. `frames_dir`, when not empty, receives overview PNGs of the stages.
/// Throws std::invalid_argument for an unknown tool or bad options; failures are results.
PullCaseResult RunPullCase(const LoadedScene& scene, const std::string& tool, std::uint64_t seed,
                           const PullCaseOptions& options = {}, const std::filesystem::path& frames_dir = {});

/// Protocol "pull-gt": every library tool (sorted by name; case index = tool index), seed of
/// case i = DeriveSeed(request seed, "pull/<tool>"), each case in its own process (RunSweep:
/// results.jsonl, --jobs, --resume, --shard). Writes summary.json: pull_success_rate (ball ends
/// within reach, BallInReach), per-family mean displacement toward the robot and success rate,
/// ball-grasp success; and summary.md with per-family bar charts.
int RunPullBench(const BenchRequest& request);

/// Writes summary.json, summary.md and its plots from pull-gt results lines (this run's or
/// merged shards').
void ReportPull(const BenchRequest& request, const std::vector<SweepLine>& lines);

}  // namespace toolbench::app
