#include "app/scoring.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace toolbench::app {
namespace {

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const double c = a.normalized().dot(b.normalized());
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / M_PI;
}

bool HasSymmetry(const toollib::ToolModel& model, const std::string& name) {
  return std::find(model.symmetries.begin(), model.symmetries.end(), name) != model.symmetries.end();
}

CellScore ScoreAgainst(const perception::ToolAnalysis& analysis, const toollib::ToolModel& true_model,
                       const Eigen::Isometry3d& X_RT_true, const CellScoreOptions& options) {
  CellScore s;
  const Eigen::Vector3d center_true = X_RT_true * true_model.handle.center;
  const Eigen::Vector3d axis_true = X_RT_true.linear() * true_model.handle.axis.normalized();
  s.handle_error_m = (analysis.handle.center - center_true).norm();
  s.axis_error_deg = AngleDeg(analysis.handle.axis, axis_true);
  const bool x_free = HasSymmetry(true_model, "rot_z_any");
  s.effector_error_deg = x_free ? 0.0 : AngleDeg(analysis.X_RT.linear().col(0), X_RT_true.linear().col(0));
  const bool axis_ok = s.axis_error_deg <= options.max_axis_error_deg;
  const bool flipped = s.axis_error_deg >= 180.0 - options.max_axis_error_deg;
  const bool center_ok = s.handle_error_m <= options.max_center_error_m;
  const bool effector_ok = s.effector_error_deg <= options.max_effector_error_deg;
  if (axis_ok && center_ok && effector_ok) {
    s.score = 1.0;
    s.verdict = "perfect";
  } else if (axis_ok && center_ok) {
    s.score = 0.5;
    s.verdict = "effector_wrong_side";
  } else if (flipped) {
    s.score = 0.5;
    s.verdict = "flipped";
  } else if (axis_ok) {
    s.verdict = "centre_off";
  } else {
    s.verdict = "axis_wrong";
  }
  return s;
}

}  // namespace

CellScore ScoreCell(const perception::ToolAnalysis& analysis, const toollib::ToolModel& true_model,
                    const Eigen::Isometry3d& X_RT_true, const std::string& fitted_family,
                    const CellScoreOptions& options) {
  CellScore best;
  best.verdict = "not_found";
  if (analysis.status != perception::AnalysisStatus::kOk) return best;
  std::vector<Eigen::Isometry3d> truths = {X_RT_true};
  if (HasSymmetry(true_model, "rot_x_180")) {
    // The same shape turned end to end about its middle: z_T -> -z_T, origin at
    // the other end.
    Eigen::Isometry3d X_TT = Eigen::Isometry3d::Identity();
    X_TT.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
    X_TT.translation() = Eigen::Vector3d(0, 0, true_model.total_length);
    truths.push_back(X_RT_true * X_TT);
  }
  if (HasSymmetry(true_model, "rot_z_180")) {
    // The same shape turned half about the handle axis: both working sides are right.
    Eigen::Isometry3d X_TT = Eigen::Isometry3d::Identity();
    X_TT.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const size_t count = truths.size();
    for (size_t i = 0; i < count; ++i) truths.push_back(truths[i] * X_TT);
  }
  for (size_t i = 0; i < truths.size(); ++i) {
    const CellScore s = ScoreAgainst(analysis, true_model, truths[i], options);
    if (i == 0 || s.score > best.score || (s.score == best.score && s.handle_error_m < best.handle_error_m)) {
      best = s;
    }
  }
  best.recognised = analysis.model == true_model.name;
  best.family_recognised = !fitted_family.empty() && fitted_family == true_model.family;
  return best;
}

}  // namespace toolbench::app
