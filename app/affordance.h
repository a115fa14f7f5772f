#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "perception/tool_analysis.h"

namespace toolbench::app {

/// Names of the affordance features, in the order AffordanceFeatures returns them. Lengths in
/// metres; the superquadric exponents are unitless.
///   total_length, handle_length, handle_radius      ToolFeatures (tool frame T)
///   effector_x_T, effector_z_T                      effector centre in T (y_T is ~0 for every tool)
///   effector_size_x/y/z, effector_protrusion        ToolFeatures
///   effector_sq_a1/a2/a3, effector_sq_e1/e2         superquadric of the effector part (largest
///                                                   non-handle part), semi-axes sorted decreasing;
///                                                   zero size, e = 1 for a one-part tool (a stick)
///   effector_x_G, effector_y_G, effector_z_G        effector centre in the hand's grasp frame G
///   working_x_G, working_y_G, working_z_G           the tool's working side (+x_T) in G
/// The last six are the tool's pose in the hand (the original tool-affordance work's "tool pose").
const std::vector<std::string>& AffordanceFeatureNames();

/// The affordance feature vector of one tool held in the hand. Everything comes from perception
/// and from what the robot knows about its own grasp, never from the simulator:
///  - `parts`, `handle_part`, `features`: the shape analysis of the tool (perception::ToolAnalysis
///    or perception::ModelShape; parts in any frame, features in T);
///  - `X_GT`: the tool frame T in the grasp frame G (PalmGraspFrame), i.e. X_PG^-1 * X_PT with X_PT
///    the tool in the palm as the grasp plan or the hand-over put it.
/// Throws std::invalid_argument when handle_part is not an index into parts or X_GT / the features
/// are not finite.
Eigen::VectorXd AffordanceFeatures(const std::vector<perception::Part>& parts, int handle_part,
                                   const perception::ToolFeatures& features, const Eigen::Isometry3d& X_GT);

/// The tool in the hand's grasp frame G for a tool held by its handle frame H (X_TH: handle in
/// T, z_H along the handle) with the handle axis on the grasp axis, H turned by `roll_rad` about
/// that axis (0 = x_H along x_G): X_GT = Rz(roll) * X_TH^-1.
Eigen::Isometry3d HeldToolPose(const Eigen::Isometry3d& X_TH, double roll_rad);

/// One exploration trial as the regressor learns from it.
struct AffordanceSample {
  std::string tool;     // library model (held-out evaluation groups by it or by family)
  std::string family;   // tool family ("hoe", "rake", ...)
  std::string action;   // "pull", "drag-left", "drag-right", "push"
  Eigen::VectorXd x;    // AffordanceFeatures
  double displacement_m = 0.0;  // achieved ball displacement along the action's direction [m]
};

/// Reads the samples of an exploration run: every successful line of results.jsonl (RunSweep
/// format, {"id", "ok": true, "result": {"tool", "family", "action", "features",
/// "displacement_along_m", "labelled"}}) whose result is labelled (the tool was in the hand when
/// the action ran), ordered by trial id (the order trials finished in does not matter). Throws
/// std::invalid_argument naming the file and line for a missing file, malformed JSON or features
/// of the wrong length.
std::vector<AffordanceSample> ReadAffordanceSamples(const std::filesystem::path& results_jsonl);

/// Hyper-parameter candidates of the Gaussian-process regressor, chosen per action by the largest
/// log marginal likelihood (a deterministic grid search, no random restarts).
struct AffordanceTrainOptions {
  /// RBF length scales [standardised feature units], each > 0.
  std::vector<double> length_scales{1.0, 1.5, 2.0, 3.0, 4.5, 7.0};
  /// Signal variance as a fraction of the targets' variance, each > 0.
  std::vector<double> signal_fractions{0.1, 0.3, 1.0, 3.0};
  /// Noise variance as a fraction of the targets' variance, each > 0. The grid reaches past 1 so
  /// that "the features explain (almost) nothing" is a hypothesis the likelihood can pick: the
  /// GP then stays near the mean instead of fitting noise (exploration outcomes are noisy: a
  /// skill that fails, a ball knocked off the table).
  std::vector<double> noise_fractions{0.02, 0.05, 0.1, 0.2, 0.4, 1.0, 3.0};
  /// Smallest standard deviation a feature is divided by when standardised [feature units], > 0:
  /// a feature that hardly varies in the training set is not blown up to unit scale.
  double min_feature_scale = 1e-3;
  void Validate() const;  // throws std::invalid_argument naming the field and its value
};

/// Expected effect of an action with a tool.
struct AffordancePrediction {
  double displacement_m = 0.0;  // expected ball displacement along the action's direction [m]
  double std_m = 0.0;           // standard deviation of that expectation (GP posterior, without noise) [m]
};

/// The learned affordance model: per action, a Gaussian-process regression from the standardised
/// AffordanceFeatures to the ball displacement along the action's direction.
///
/// Why a Gaussian process: exploration gives a few hundred trials per action and the features
/// are continuous geometry, so the exact GP (an O(n^3) Cholesky of a few hundred rows, under a
/// second) is affordable and needs no iterative training; it interpolates smoothly between tools
/// instead of copying the nearest one (k-NN's step changes when a held-out tool sits between
/// families), its hyper-parameters come from the marginal likelihood (no validation split taken
/// from the little data there is), it returns the mean it falls back to far from the data (a
/// tool unlike any explored one gets the average effect, not an arbitrary neighbour's), and its
/// posterior variance says how sure the prediction is. The original tool-affordance work used a
/// GRNN, a kernel regressor of the same family.
class AffordanceModel {
 public:
  AffordanceModel() = default;

  /// Fits one GP per action present in `samples`. Throws std::invalid_argument for bad options,
  /// an action with fewer than 2 samples, feature vectors of the wrong length or non-finite values.
  static AffordanceModel Train(const std::vector<AffordanceSample>& samples, const AffordanceTrainOptions& options = {});

  /// Reads a model written by Save. Throws std::invalid_argument naming the file and what is
  /// wrong: missing or unreadable, not JSON, another format or version, features other than
  /// AffordanceFeatureNames(), inconsistent sizes or non-finite numbers.
  static AffordanceModel Load(const std::filesystem::path& file);

  /// Writes the model as JSON (training inputs, targets, hyper-parameters and `info`): the same
  /// model gives the same bytes. Throws std::runtime_error when the file cannot be written.
  void Save(const std::filesystem::path& file) const;

  /// Expected effect of `action` for features `x` (AffordanceFeatures). Throws
  /// std::invalid_argument for an action the model was not trained on (naming the known ones) or
  /// an x of the wrong length or non-finite.
  AffordancePrediction Predict(std::string_view action, const Eigen::VectorXd& x) const;

  bool HasAction(std::string_view action) const;
  std::vector<std::string> actions() const;  // sorted
  int samples(std::string_view action) const;  // training samples of an action (0 when absent)

  /// Free-form provenance saved with the model (command, seed, orientations, trial counts).
  nlohmann::json info = nlohmann::json::object();

 private:
  struct ActionGp {
    Eigen::VectorXd x_mean, x_scale;  // standardisation of the features
    double y_mean = 0.0;              // mean target [m]
    double length_scale = 1.0, signal_var = 1.0, noise_var = 1.0;
    Eigen::MatrixXd X;                // n x d standardised training inputs
    Eigen::VectorXd y;                // n targets [m]
    std::vector<std::string> tools;   // tool of each row (provenance)
    Eigen::MatrixXd L;                // Cholesky factor of K + noise I
    Eigen::VectorXd alpha;            // (K + noise I)^-1 (y - y_mean)
    double log_likelihood = 0.0;
  };
  static void Factor(ActionGp& gp);
  nlohmann::json ToJson() const;
  std::map<std::string, ActionGp, std::less<>> gps_;
};

/// How held-out evaluation groups the samples: every group is left out once.
enum class HoldOut { kFamily, kTool };

/// Held-out error of the model against always predicting the training mean, one action or all.
struct HeldOutScore {
  std::string action;      // "all" for the pooled row
  int samples = 0;
  int groups = 0;          // groups left out (families or tools)
  double mae_model_m = 0.0, mae_mean_m = 0.0;    // mean absolute error [m]
  double rmse_model_m = 0.0, rmse_mean_m = 0.0;  // root mean square error [m]
  /// Per left-out group, mean of the model's prediction and of the achieved displacement (does
  /// the model rank the unseen tools?): Spearman-free, just the Pearson correlation of the two
  /// over groups, NaN with fewer than 3 groups or no spread.
  double group_correlation = 0.0;
};

/// Result of EvaluateHeldOut.
struct HeldOutReport {
  HoldOut by = HoldOut::kFamily;
  std::vector<HeldOutScore> per_action;  // sorted by action
  HeldOutScore overall;                  // all actions pooled
};

/// Leave-one-group-out: for each family (or tool), trains on the other groups' samples (the same
/// Train, hyper-parameters chosen again) and predicts the left-out group's; the baseline predicts
/// the training mean of the action. Actions whose training fold has fewer than 2 samples are
/// skipped for that fold. Throws std::invalid_argument for fewer than 2 groups.
HeldOutReport EvaluateHeldOut(const std::vector<AffordanceSample>& samples, HoldOut by,
                              const AffordanceTrainOptions& options = {});

/// The report as JSON (for evaluation.json).
nlohmann::json HeldOutJson(const HeldOutReport& report);

}  // namespace toolbench::app
