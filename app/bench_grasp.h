#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "app/bench.h"
#include "app/scene_setup.h"
#include "control/skills.h"

namespace toolbench::app {

/// How one ground-truth grasp case is judged (issue 4): after GraspHandle lifted the tool, the
/// hand holds it for `hold_time`; success = the tool rose at least `min_lift_m` above its rest
/// height, the point of the handle's axis nearest the hand's grasp centre when the hold begins
/// (where the hand holds it) moved less than `max_slip_m` in the palm frame during the hold, and
/// the tool touched only robot bodies ("r_" prefix) during the hold.
struct GraspCaseOptions {
  double hold_time = 2.0;       // judged hold [s], > 0
  double min_lift_m = 0.05;     // [m], > 0
  double max_slip_m = 0.005;    // [m], > 0
  double sample_period = 0.05;  // contact / slip sampling period during the hold [s], > 0
  /// Let the grasp centre slide along the handle: sets grasp.handle_slide to GripSlide of the
  /// tool's model (the ground-truth handle segment, and the bar past it) with slide_margin_m.
  bool slide_along_handle = true;
  double slide_margin_m = 0.01;  // [m], >= 0
  /// Grasp as the episode does: after the look at the rack (LookAt RackViewTarget with the arm
  /// down: the torso turned toward the rack, the hand hanging beside the hip, below the top of the
  /// rack's ledge) instead of from the home posture.
  bool from_rack_look = false;
  control::GraspOptions grasp;   // the skill's options
  void Validate() const;         // throws std::invalid_argument naming the field and its value
};

/// Outcome of one case (tool in cell, new World).
struct GraspCaseResult {
  std::string tool;
  std::string cell;
  bool success = false;
  std::string reason;                         // empty on success: the skill's status/reason, or the failed criterion
  control::GraspResult grasp;                 // what the skill reported
  double lift_m = 0.0;                        // tool origin height above its settled rest height after the lift [m]
  double palm_rise_m = 0.0;           // palm height at the end above the planned grasp pose (ground truth) [m]
  double slip_m = 0.0;  // largest displacement in P of the handle axis point held (above), in the hold [m]
  double handle_centre_slip_m = 0.0;          // the same of the handle centre (apart by the grasp's slide) [m]
  double slip_rad = 0.0;                      // largest rotation of the tool relative to P during the hold [rad]
  std::vector<std::string> foreign_contacts;  // non-robot bodies the tool touched during the hold
  std::vector<std::string> robot_contacts;    // "robot body-other body" touching when the skill ended
  bool settled = false;                       // the tool came to rest on the rack before the grasp
  /// Where the true handle axis passed the hand's grasp cylinder at each stage of the skill
  /// ("at_grasp", "closed", "lifted"): its offset from the cylinder's centre, perpendicular to the
  /// handle axis, in the palm frame P [m] (x_P toward the thumb side, z_P out of the palm: > 0
  /// means the handle sits farther from the palm than planned, toward the fingertips), and the
  /// angle between the two axes [rad]. Ground truth, for diagnosing empty hands and drops.
  /// Also how far the handle centre had moved from its rest and how far the palm was from the
  /// planned grasp pose [m] (the two tell a tool pushed by the approach from a hand that stopped
  /// short).
  struct HandleInHand {
    std::string stage;
    Eigen::Vector3d offset_P = Eigen::Vector3d::Zero();
    double angle_rad = 0.0;
    double handle_moved_m = 0.0;
    double palm_off_plan_m = 0.0;
    Eigen::Vector3d p_RP = Eigen::Vector3d::Zero();  // the true palm position [m]
    std::vector<std::string> contacts;  // "robot body-other body" touching then (the tool included)
  };
  std::vector<HandleInHand> handle_in_hand;
  double sim_time = 0.0;                      // simulated time of the whole case, settling included [s]
  double wall_ms = 0.0;                       // [ms], informational
};

/// Runs one case: composes `scene` with only `tool` in `cell`, settles it, grasps the handle
/// from its ground-truth pose (X_RT times the handle segment: this isolates control from
/// perception), lifts, holds and scores. Never throws for a failed grasp (it is a result).
/// Throws std::invalid_argument for an unknown tool or cell, or bad options. `frame_png`, when
/// not empty, receives an overview image of the end of the case, and <stem>_<stage>.png one of
/// each stage of the grasp (GraspOptions::on_stage).
GraspCaseResult RunGraspCase(const LoadedScene& scene, const std::string& tool, const std::string& cell,
                             std::uint64_t seed, const GraspCaseOptions& options = {},
                             const std::filesystem::path& frame_png = {});

/// Protocol "grasp-gt": every library tool in each of the 7 cells (pos1 pos2 pos3 rot0 rot1
/// rot2 rot3), case index = tool index * 7 + cell index, grasped from the ground-truth handle
/// pose with RunGraspCase, each case in its own process (RunSweep: results.jsonl lines with tool,
/// cell, success, reason, lift_m, slip_m, sim_time_s, wall_ms, ...; --jobs, --resume, --shard).
/// Writes summary.json (grasp_success_rate, per_tool, per_cell, failure_reasons) and summary.md
/// with per-cell and per-tool bar charts. Returns 0 when the run completed.
int RunGraspBench(const BenchRequest& request);

/// Writes summary.json, summary.md and its plots from grasp-gt results lines (this run's or
/// merged shards').
void ReportGrasp(const BenchRequest& request, const std::vector<SweepLine>& lines);

}  // namespace toolbench::app
