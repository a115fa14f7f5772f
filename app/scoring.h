#pragma once

#include <Eigen/Geometry>
#include <string>

#include "perception/tool_analysis.h"
#include "toollib/tool_model.h"

namespace toolbench::app {

/// Thresholds of the Table 5.3 cell score (design.md, "Scoring the thesis's
/// Table 5.3").
struct CellScoreOptions {
  double max_axis_error_deg = 15.0;      // handle axis within this of the truth [deg]
  double max_center_error_m = 0.02;      // handle centre within this of the truth [m]
  double max_effector_error_deg = 60.0;  // working direction x_T within this of the truth [deg]
};

/// One tool of one cell, scored against ground truth.
struct CellScore {
  double score = 0.0;               // 1, 0.5 or 0
  std::string verdict;              // "perfect", "flipped", "effector_wrong_side",
                                    // "axis_wrong", "centre_off", "not_found"
  double handle_error_m = 0.0;      // |fitted handle centre - true handle centre| [m]
  double axis_error_deg = 0.0;      // angle between fitted and true handle axes [deg], in [0, 180]
  double effector_error_deg = 0.0;  // angle between fitted and true x_T [deg]; 0 when x_T is free
  bool recognised = false;          // model name equals the true one
  bool family_recognised = false;   // model family equals the true one
};

/// Scores one analysed tool against the truth:
///  - 1 when the handle axis is within max_axis_error_deg, the handle centre
///  within
///    max_center_error_m and the effector's working direction within
///    max_effector_error_deg;
///  - 0.5 when the main axis is right as a line but the tool is flipped end to
///  end (axis error
///    >= 180 - max_axis_error_deg), or the handle is right but the effector
///    faces another side;
///  - 0 otherwise.
/// The truth is the true model's sidecar handle placed with the true pose
/// X_RT_true; the model's symmetries count ("rot_z_any": x_T is free;
/// "rot_x_180": an end-to-end flip is the same shape, so the flipped truth is
/// scored too and the better score kept).
CellScore ScoreCell(const perception::ToolAnalysis& analysis, const toollib::ToolModel& true_model,
                    const Eigen::Isometry3d& X_RT_true, const std::string& fitted_family,
                    const CellScoreOptions& options = {});

}  // namespace toolbench::app
