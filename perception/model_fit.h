#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "common/types.h"
#include "toollib/mesh.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {

/// Points sampled on a mesh surface, with the unit outward normal of the face each came from.
/// Both are in the mesh's frame (the tool frame T for library tools) [m].
struct SurfaceSamples {
  Eigen::Matrix3Xf points;   // 3 x N sample positions [m]
  Eigen::Matrix3Xf normals;  // 3 x N unit outward face normals
  std::vector<int> faces;    // N indices of the mesh face each sample lies on (SampleSurface
                             // fills it; empty for clouds that do not come from a mesh)
};

/// Area-weighted uniform sampling of a triangle mesh (thesis 2.3.4): a face is picked with
/// probability proportional to its area, then a point uniformly inside it (square-root
/// barycentric trick). Same mesh, count and seed give bit-identical samples on every platform
/// (draws use toolbench::UniformReal on an Rng seeded with `seed`).
/// Throws std::invalid_argument when `count` <= 0, the mesh has no faces, a face index is out
/// of range, or the total area is zero.
SurfaceSamples SampleSurface(const toollib::TriangleMesh& mesh, int count, std::uint64_t seed);

/// Error metric ICP minimises.
enum class IcpMetric {
  kPointToPoint,  // pcl::IterativeClosestPoint, the thesis's baseline
  kPointToPlane,  // damped point-to-plane steps (model normals from the mesh faces): slides along
                  // the handle far better than point-to-point. The candidate search and the
                  // light verification run our own ICP loop (2-3x faster than PCL's), the final
                  // refinement pcl::IterativeClosestPoint
};

/// Configuration of the model-to-cloud fit. The ICP stopping criteria are the thesis's
/// Algorithm 4 (500 iterations, transformation epsilon 1e-9, Euclidean fitness epsilon 1e-6);
/// the thesis's baseline is `metric = kPointToPoint, try_flips = false, visible_rounds = 0`
/// (with our principal-axes initial guess; the thesis's own initial guess is not stated). The
/// candidate search, the point-to-plane metric and the visible-surface rounds are additions.
struct ModelFitOptions {
  IcpMetric metric = IcpMetric::kPointToPlane;  // see IcpMetric
  int model_points = 4000;                 // samples on the library mesh (thesis: 4000), > 0
  std::uint64_t sample_seed = 1;           // seed of the model sampling
  int max_observed_points = 2000;          // the observed cloud is subsampled (evenly, by index)
                                           // to at most this many points for ICP, >= 10
  int max_iterations = 500;                // ICP iteration cap of the final fit (thesis), > 0
  double transformation_epsilon = 1e-9;    // ICP convergence on the transform change (thesis), >= 0
  double euclidean_fitness_epsilon = 1e-6;  // ICP convergence on the MSE change (thesis), >= 0
  double max_correspondence_distance = 0.05;  // ICP pairs farther apart are ignored [m], > 0
  int coarse_points = 300;                 // observed points used to rank the candidates, >= 10
  int coarse_iterations = 40;              // ICP cap for scoring each initial candidate, > 0
  int screen_iterations = 10;              // > 0: every candidate first gets this many ICP
                                           // iterations and is scored; only the screen_keep best
                                           // continue to coarse_iterations. 0 = no screening
                                           // (every candidate runs coarse_iterations), >= 0
  int screen_keep = 3;                     // candidates kept by the screening, > 0
  bool try_flips = true;                   // false: only the principal-axes alignment (no flips)
  int spin_steps = 4;                      // with try_flips: turns about the main axis tried, every
                                           // 360 / spin_steps deg, for each direction of the main
                                           // axis (2 * spin_steps candidates), in [1, 36]
  int visible_rounds = 2;                  // with a camera: refinements against the camera-facing
                                           // model samples only (re-selected each round), >= 0
  double visible_distance = 0.01;          // a visible model point farther than this from every
                                           // observed point counts as unexplained [m], > 0
  double unexplained_weight = 0.02;        // score = fit_error + weight * unexplained fraction
                                           // [m per unit fraction], >= 0
  int score_model_points = 1000;           // model samples (an even subset of model_points) whose
                                           // visibility scores each candidate of the search; the
                                           // final score uses all of them, >= 10
  // Depth-image check of the turn about the handle axis (needs a FitView; the thesis baseline
  // has none: view_spin_steps = 0). After the final ICP the fitted model is turned about its
  // handle axis every 360 / view_spin_steps deg, each turn also flipped end to end, and every
  // hypothesis is scored against the depth image; the view_keep best get a short ICP, and the
  // winner, when it is not the ICP result, is refined again.
  int view_spin_steps = 24;                // turns tried, in [0, 72]; 0 = no depth-image check
  int view_points = 150;                   // observed points (an even subset) whose distance to
                                           // the model ranks the hypotheses, >= 10
  int view_keep = 4;                       // hypotheses refined after the ranking, > 0
  int view_iterations = 15;                // ICP cap of each of those refinements and of each
                                           // round of the winner's re-refinement, > 0
  int view_refine_points = 600;            // observed points (an even subset) of the winner's
                                           // re-refinement against its visible samples, >= 10
  double view_free_distance = 0.01;        // a model sample this much in front of the observed
                                           // depth is a free-space violation [m], > 0
  double view_weight = 0.02;               // hypothesis cost = mean observed-to-model distance +
                                           // view_weight * violated fraction [m per unit], >= 0
  void Validate() const;                   // throws std::invalid_argument naming the field
};

/// What the camera saw of one tool: lets the fit check a pose against the depth image itself
/// (free space the camera saw through, pixels outside the tool's mask), which the cloud alone
/// cannot tell (ModelFitOptions::view_spin_steps).
struct FitView {
  cv::Mat depth;                                           // CV_32FC1 [m] along the optical axis, 0 = no return
  cv::Mat mask;                                            // CV_8UC1 of depth's size, non-zero = this tool
  CameraIntrinsics intrinsics;                             // of `depth`; width and height must match it
  Eigen::Isometry3d X_RC = Eigen::Isometry3d::Identity();  // camera (OpenCV frame) in R
};

/// Outcome class of a fit (an expected failure is a result, not an exception).
enum class FitStatus {
  kOk,            // a pose was found
  kTooFewPoints,  // the observed cloud has fewer than kMinFitPoints points
};

/// Smallest observed cloud a fit is attempted on.
inline constexpr int kMinFitPoints = 10;

/// One initial guess tried by the fit and where ICP took it.
struct FitCandidate {
  std::string label;  // "main_<a>": principal axes aligned, then turned by <a> deg about the
                      // main axis (a = k * 360 / spin_steps: 0/90/180/270 by default); "rev_<a>":
                      // the same after 180 deg about the second axis (main axis reversed).
                      // main_180 and rev_0/rev_180 are the 180-degree flips about each axis.
  Eigen::Isometry3d X_RT_initial = Eigen::Isometry3d::Identity();  // guess, tool in root R
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();          // after the coarse ICP
  double fit_error = 0.0;     // mean observed-to-model distance after the coarse ICP [m]
  double unexplained = 0.0;   // fraction of camera-facing model points with no observed point
                              // within visible_distance, in [0, 1]; 0 without a camera
  double score = 0.0;         // fit_error + unexplained_weight * unexplained [m]; lower = better
  bool converged = false;     // PCL's hasConverged() of the coarse ICP
};

/// Pose of a library model fitted to an observed (partial) cloud.
struct ModelFitResult {
  FitStatus status = FitStatus::kTooFewPoints;
  std::string reason;      // empty when kOk
  std::string model;       // library model name
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();  // tool frame T in the root R
  double fit_error = 0.0;  // mean distance observed point -> nearest model point [m]
  double unexplained = 0.0;  // see FitCandidate::unexplained, for the final pose
  double score = 0.0;      // see FitCandidate::score, for the final pose [m]
  bool converged = false;  // PCL's hasConverged() of the final ICP
  int iterations = 0;      // ICP iteration cap used by the final fit
  std::vector<FitCandidate> candidates;  // every initial guess, in the order tried
  int best_candidate = -1;               // index into `candidates` the final fit started from
  // With a view check: the winning turn about the handle axis ("spin_<deg>", "flip_<deg>";
  // "spin_0" = the ICP result kept); else empty.
  std::string view_turn;
  // With a view check: fraction of the camera-facing model samples the depth image
  // contradicts (seen through, or outside the mask) at X_RT, in [0, 1]; else 0.
  double violation = 0.0;
};

/// Fits one library model to observed clouds. Construction samples the model
/// (ModelFitOptions::model_points, area-weighted) and builds its search structure once; Fit
/// can then be called for many clouds.
///
/// Fit direction: source = observed cloud, target = model (measured.md: fitting the full model
/// into a partial view biases the pose by ~9 mm / 3.5 deg). Initialisation: the principal axes
/// of the observed cloud are aligned to the model's (main axis to main axis, centroids
/// together), then the 180-degree flips about each model axis and the 90/270-degree turns about
/// the main axis (the Table 5.3 rot1-rot3 cases) are tried with a short ICP; the best score
/// wins and is refined by the full ICP.
class ModelFitter {
 public:
  /// Throws std::invalid_argument for bad options (Validate) or a model whose mesh cannot be
  /// sampled (see SampleSurface).
  ModelFitter(const toollib::ToolModel& model, const ModelFitOptions& options);
  ~ModelFitter();
  ModelFitter(ModelFitter&&) noexcept;
  ModelFitter& operator=(ModelFitter&&) noexcept;

  /// Fits the model to `p_R` (3 x N observed points in the root frame R [m]).
  /// `p_R_camera`, when given, is the camera centre in R; it lets the score count the
  /// camera-facing model surface the observation does not explain (a partial cloud otherwise
  /// fits inside any larger model). Returns kTooFewPoints with a reason for fewer than
  /// kMinFitPoints points. `view`, when given (and view_spin_steps > 0), checks the turn about
  /// the handle axis against the depth image after the final ICP (see ModelFitOptions).
  /// Throws std::invalid_argument when `p_R` has a non-finite entry, or for a `view` whose
  /// depth is empty or not CV_32FC1, whose mask is not CV_8UC1 of the depth's size, or whose
  /// intrinsics do not match the depth or have non-positive focal lengths.
  ModelFitResult Fit(const Eigen::Matrix3Xf& p_R, const std::optional<Eigen::Vector3d>& p_R_camera = std::nullopt,
                     const std::optional<FitView>& view = std::nullopt) const;

  /// The first stage of Fit alone: every initial candidate with the short ICP (coarse_points,
  /// coarse_iterations; screened first when screen_iterations > 0), scored. X_RT, fit_error,
  /// unexplained and score are the best candidate's; iterations = coarse_iterations.
  /// Same arguments, results and exceptions as Fit.
  ModelFitResult Search(const Eigen::Matrix3Xf& p_R,
                        const std::optional<Eigen::Vector3d>& p_R_camera = std::nullopt) const;

  /// The second stage of Fit: the full ICP (and visible-surface rounds) from the pose X_RT of
  /// `searched`, which must be a kOk Search (or Refine) result of this fitter on the same `p_R`
  /// and `p_R_camera`, then the depth-image check when `view` is given.
  /// Fit(p, c, v) == Refine(p, c, Search(p, c), v). Throws std::invalid_argument for a
  /// `searched` of another model or not kOk, fewer than kMinFitPoints or non-finite points, or
  /// a bad `view` (see Fit).
  ModelFitResult Refine(const Eigen::Matrix3Xf& p_R, const std::optional<Eigen::Vector3d>& p_R_camera,
                        ModelFitResult searched, const std::optional<FitView>& view = std::nullopt) const;

  /// Refine with other limits than the options': at most `max_observed_points` (>= 10) observed
  /// points and `max_iterations` (> 0) ICP iterations per round (ToolRecognizer verifies
  /// candidate models with a light refinement); never runs the depth-image check. Throws
  /// std::invalid_argument also for limits out of range.
  ModelFitResult Refine(const Eigen::Matrix3Xf& p_R, const std::optional<Eigen::Vector3d>& p_R_camera,
                        ModelFitResult searched, int max_observed_points, int max_iterations) const;

  /// The model samples in T (for display and tests).
  const SurfaceSamples& samples() const;
  /// The library model name.
  const std::string& name() const;
  /// Extents of the model samples along their principal axes, largest first [m].
  const Eigen::Vector3d& principal_extents() const;

 private:
  // The Refine overloads: own_loop selects our ICP loop (verification) or PCL's (final fit).
  ModelFitResult RefineWith(const Eigen::Matrix3Xf& p_R, const std::optional<Eigen::Vector3d>& p_R_camera,
                            ModelFitResult searched, int max_observed_points, int max_iterations, bool own_loop,
                            const FitView* view) const;

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Options of ToolRecognizer.
struct RecognitionOptions {
  ModelFitOptions fit;        // used for every model
  int max_models = 6;         // without a classifier prior: models verified after the extent
                              // pre-selection, > 0
  int max_classifier_candidates = 3;  // with a prior: at most this many models verified, > 0
  int verify_points = 500;    // observed points of the light refinement that verifies each
                              // candidate model after its pose search, >= 10
  int verify_iterations = 30;  // ICP cap per round of that refinement, > 0
  double classifier_mass = 0.95;      // with a prior: models are verified in decreasing
                                      // probability until they hold this much of it, (0, 1]
  double min_classifier_probability = 0.05;  // with a prior: a model less probable than this
                                             // is not verified (the most probable one always
                                             // is), [0, 1)
  double confidence_scale = 0.002;  // temperature of the fit likelihood exp(-score / scale) [m], > 0
  void Validate() const;      // throws std::invalid_argument naming the field
};

/// One model's result inside RecognizeTool.
struct ModelScore {
  std::string model;           // library model name
  double extent_distance = 0;  // cheap pre-selection distance (relative extent mismatch)
  double prior = 0;            // classifier probability; 0 without a classifier
  bool fitted = false;         // verified (pose search run); false when not selected
  double score = 0;            // score after the verifying refinement when fitted [m]
  double posterior = 0;        // prior (1 without one) x fit likelihood, normalised over the
                               // verified models; 0 when not fitted
};

/// Best library model for one observed cloud.
struct RecognitionResult {
  FitStatus status = FitStatus::kTooFewPoints;
  std::string reason;        // empty when kOk
  std::string model;         // best model's name
  double confidence = 0.0;   // the winner's posterior (see ModelScore) times the prior mass of the
                             // verified models (1 without a prior), (0, 1]
  ModelFitResult fit;        // the best model's full fit
  std::vector<ModelScore> scores;  // every library model, in library order
};

/// Recognises a tool among the library models and fits the winner. Colour-free.
/// Candidates: with a classifier prior (ToolClassifier::PredictForLibrary), the most probable
/// models until they hold `classifier_mass` of the probability, at most
/// `max_classifier_candidates`, none below `min_classifier_probability` but the first; without one (the fallback), the `max_models` models whose
/// principal extents best match the cloud's (observed length may be shorter than the model's
/// when occluded, never much longer). Verification: each candidate's pose search
/// (ModelFitter::Search) and a light refinement (verify_points, verify_iterations) score it;
/// the winner maximises prior x exp(-score / confidence_scale) and alone gets the full
/// refinement (ModelFitter::Refine). Construction samples every model once.
class ToolRecognizer {
 public:
  /// Throws std::invalid_argument for bad options, an empty library, or a model that cannot be
  /// sampled.
  ToolRecognizer(const std::vector<toollib::ToolModel>& library, const RecognitionOptions& options);
  ~ToolRecognizer();
  ToolRecognizer(ToolRecognizer&&) noexcept;
  ToolRecognizer& operator=(ToolRecognizer&&) noexcept;

  /// See the class comment; arguments as ModelFitter::Fit. Returns kTooFewPoints with a reason
  /// for a cloud too small to fit; throws std::invalid_argument for non-finite points.
  /// `prior`, when not empty, is a probability per library model (library order, >= 0).
  /// Throws std::invalid_argument also for a prior of the wrong length or a negative entry.
  /// `view`, when given, reaches the winner's full refinement (ModelFitter::Refine; the
  /// candidates' verification does not use it); a bad view throws as in ModelFitter::Fit.
  RecognitionResult Recognize(const Eigen::Matrix3Xf& p_R,
                              const std::optional<Eigen::Vector3d>& p_R_camera = std::nullopt,
                              const std::vector<double>& prior = {},
                              const std::optional<FitView>& view = std::nullopt) const;

  /// The library model names, in library order (the order a prior must follow).
  std::vector<std::string> model_names() const;

  /// The fitter of library model `index` (library order).
  const ModelFitter& fitter(int index) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Extents of a cloud along its principal axes, largest first [m] (the cheap feature
/// RecognizeTool pre-selects with). Zero for fewer than 2 points.
Eigen::Vector3d PrincipalExtents(const Eigen::Matrix3Xf& points);

}  // namespace toolbench::perception
