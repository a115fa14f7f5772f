#include "perception/model_fit.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include <Eigen/Eigenvalues>
#include <pcl/console/print.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/icp.h>
#include <pcl/registration/transformation_estimation.h>
#include <pcl/search/kdtree.h>
#include <spdlog/spdlog.h>

#include "common/check.h"
#include "common/rng.h"
#include "perception/internal/log.h"

namespace toolbench::perception {
namespace {

using Point = pcl::PointNormal;
using Cloud = pcl::PointCloud<Point>;

Point MakePoint(const Eigen::Vector3d& p) {
  Point out;
  out.getVector3fMap() = p.cast<float>();
  out.getNormalVector3fMap() = Eigen::Vector3f::Zero();
  return out;
}

// Normals are optional (the observed cloud has none; point-to-plane uses the target's only).
Cloud::Ptr ToPcl(const Eigen::Matrix3Xf& points, const Eigen::Matrix3Xf* normals = nullptr) {
  auto cloud = std::make_shared<Cloud>();
  cloud->resize(static_cast<std::size_t>(points.cols()));
  for (Eigen::Index i = 0; i < points.cols(); ++i) {
    Point& p = (*cloud)[static_cast<std::size_t>(i)];
    p.getVector3fMap() = points.col(i);
    p.getNormalVector3fMap() = normals != nullptr ? Eigen::Vector3f(normals->col(i)) : Eigen::Vector3f::Zero();
  }
  return cloud;
}

// Point-to-plane step (linearised rotation, as PCL's TransformationEstimationPointToPlaneLLS)
// with a small Levenberg damping. PCL's version inverts the 6x6 normal matrix outright, which
// is singular for a shape symmetric about an axis (a stick's spin is unobservable): the NaN it
// returns then trips PCL's own kd-tree assertion in the next iteration. Damping leaves the
// unobservable direction unchanged instead.
class DampedPointToPlane : public pcl::registration::TransformationEstimation<Point, Point, float> {
 public:
  void estimateRigidTransformation(const Cloud& src, const Cloud& tgt, Matrix4& T) const override {
    Accumulate(src.size(), [&](std::size_t i) { return std::pair{i, i}; }, src, tgt, T);
  }
  void estimateRigidTransformation(const Cloud& src, const pcl::Indices& indices_src, const Cloud& tgt,
                                   Matrix4& T) const override {
    Accumulate(indices_src.size(), [&](std::size_t i) { return std::pair{static_cast<std::size_t>(indices_src[i]), i}; },
               src, tgt, T);
  }
  void estimateRigidTransformation(const Cloud& src, const pcl::Indices& indices_src, const Cloud& tgt,
                                   const pcl::Indices& indices_tgt, Matrix4& T) const override {
    Accumulate(indices_src.size(),
               [&](std::size_t i) {
                 return std::pair{static_cast<std::size_t>(indices_src[i]), static_cast<std::size_t>(indices_tgt[i])};
               },
               src, tgt, T);
  }
  void estimateRigidTransformation(const Cloud& src, const Cloud& tgt, const pcl::Correspondences& correspondences,
                                   Matrix4& T) const override {
    Accumulate(correspondences.size(),
               [&](std::size_t i) {
                 return std::pair{static_cast<std::size_t>(correspondences[i].index_query),
                                  static_cast<std::size_t>(correspondences[i].index_match)};
               },
               src, tgt, T);
  }

 private:
  template <typename Pair>
  static void Accumulate(std::size_t count, Pair pair, const Cloud& src, const Cloud& tgt, Matrix4& T) {
    Eigen::Matrix<double, 6, 6> AtA = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> Atb = Eigen::Matrix<double, 6, 1>::Zero();
    for (std::size_t k = 0; k < count; ++k) {
      const auto [i, j] = pair(k);
      const Eigen::Vector3d p = src[i].getVector3fMap().template cast<double>();
      const Eigen::Vector3d q = tgt[j].getVector3fMap().template cast<double>();
      const Eigen::Vector3d n = tgt[j].getNormalVector3fMap().template cast<double>();
      Eigen::Matrix<double, 6, 1> a;
      a << p.cross(n), n;
      AtA += a * a.transpose();
      Atb += a * n.dot(q - p);
    }
    const double damping = 1e-4 * AtA.trace() / 6.0 + 1e-12;
    AtA.diagonal().array() += damping;
    const Eigen::Matrix<double, 6, 1> x = AtA.ldlt().solve(Atb);
    Eigen::Matrix4d step = Eigen::Matrix4d::Identity();
    const Eigen::Vector3d omega = x.head<3>();
    if (omega.norm() > 0) step.topLeftCorner<3, 3>() = Eigen::AngleAxisd(omega.norm(), omega.normalized()).toRotationMatrix();
    step.topRightCorner<3, 1>() = x.tail<3>();
    T = step.allFinite() ? Matrix4(step.cast<float>()) : Matrix4::Identity();
  }
};

// Principal frame of a cloud: centroid and right-handed axes (columns), largest variance first.
struct PrincipalFrame {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
};

PrincipalFrame ComputePrincipalFrame(const Eigen::Matrix3Xf& points) {
  PrincipalFrame frame;
  const Eigen::Matrix3Xd p = points.cast<double>();
  frame.centroid = p.rowwise().mean();
  const Eigen::Matrix3Xd centred = p.colwise() - frame.centroid;
  const Eigen::Matrix3d covariance = centred * centred.transpose() / static_cast<double>(p.cols());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  // Eigen sorts eigenvalues ascending; we want the main (largest) axis first.
  for (int i = 0; i < 3; ++i) frame.axes.col(i) = solver.eigenvectors().col(2 - i);
  if (frame.axes.determinant() < 0) frame.axes.col(2) = -frame.axes.col(2);
  return frame;
}

Eigen::Vector3d ExtentsAlong(const Eigen::Matrix3Xf& points, const PrincipalFrame& frame) {
  const Eigen::Matrix3Xd local =
      frame.axes.transpose() * (points.cast<double>().colwise() - frame.centroid);
  return local.rowwise().maxCoeff() - local.rowwise().minCoeff();
}

Eigen::Matrix3Xf EvenSubsample(const Eigen::Matrix3Xf& points, int max_points) {
  if (points.cols() <= max_points) return points;
  Eigen::Matrix3Xf out(3, max_points);
  const double stride = static_cast<double>(points.cols()) / max_points;
  for (int i = 0; i < max_points; ++i) {
    out.col(i) = points.col(static_cast<Eigen::Index>(i * stride));
  }
  return out;
}

void RequireFinite(const Eigen::Matrix3Xf& p_R, const char* function) {
  if (!p_R.allFinite()) {
    ThrowInvalid(function, ": argument p_R has a non-finite coordinate (expected finite points)");
  }
}

}  // namespace

SurfaceSamples SampleSurface(const toollib::TriangleMesh& mesh, int count, std::uint64_t seed) {
  if (count <= 0) ThrowInvalid("SampleSurface: count = ", count, " (expected > 0)");
  const Eigen::Index num_faces = mesh.faces.cols();
  if (num_faces == 0) ThrowInvalid("SampleSurface: mesh has no faces (expected >= 1)");
  if (mesh.faces.minCoeff() < 0 || mesh.faces.maxCoeff() >= mesh.vertices.cols()) {
    ThrowInvalid("SampleSurface: a face index is outside [0, ", mesh.vertices.cols(), ")");
  }
  std::vector<double> cumulative(static_cast<std::size_t>(num_faces));
  std::vector<Eigen::Vector3d> normals(static_cast<std::size_t>(num_faces));
  double total = 0.0;
  for (Eigen::Index f = 0; f < num_faces; ++f) {
    const Eigen::Vector3d a = mesh.vertices.col(mesh.faces(0, f));
    const Eigen::Vector3d cross =
        (mesh.vertices.col(mesh.faces(1, f)) - a).cross(mesh.vertices.col(mesh.faces(2, f)) - a);
    const double area = 0.5 * cross.norm();
    normals[static_cast<std::size_t>(f)] = area > 0 ? Eigen::Vector3d(cross.normalized()) : Eigen::Vector3d::UnitZ();
    total += area;
    cumulative[static_cast<std::size_t>(f)] = total;
  }
  if (!(total > 0.0)) ThrowInvalid("SampleSurface: mesh surface area is ", total, " (expected > 0)");

  Rng rng(seed);
  SurfaceSamples out;
  out.points.resize(3, count);
  out.normals.resize(3, count);
  out.faces.resize(static_cast<std::size_t>(count));
  for (int i = 0; i < count; ++i) {
    const double pick = UniformReal(rng, 0.0, total);
    const auto it = std::upper_bound(cumulative.begin(), cumulative.end(), pick);
    const Eigen::Index f = std::min<Eigen::Index>(it - cumulative.begin(), num_faces - 1);
    // Uniform point in a triangle: (1 - sqrt(r1)) a + sqrt(r1)(1 - r2) b + sqrt(r1) r2 c.
    const double s = std::sqrt(UniformReal(rng, 0.0, 1.0));
    const double r2 = UniformReal(rng, 0.0, 1.0);
    const Eigen::Vector3d p = (1.0 - s) * mesh.vertices.col(mesh.faces(0, f)) +
                              s * (1.0 - r2) * mesh.vertices.col(mesh.faces(1, f)) +
                              s * r2 * mesh.vertices.col(mesh.faces(2, f));
    out.points.col(i) = p.cast<float>();
    out.normals.col(i) = normals[static_cast<std::size_t>(f)].cast<float>();
    out.faces[static_cast<std::size_t>(i)] = static_cast<int>(f);
  }
  return out;
}

Eigen::Vector3d PrincipalExtents(const Eigen::Matrix3Xf& points) {
  if (points.cols() < 2) return Eigen::Vector3d::Zero();
  return ExtentsAlong(points, ComputePrincipalFrame(points));
}

void ModelFitOptions::Validate() const {
  const char* f = "ModelFitOptions::Validate: ";
  if (model_points <= 0) ThrowInvalid(f, "model_points = ", model_points, " (expected > 0)");
  if (max_observed_points < kMinFitPoints) {
    ThrowInvalid(f, "max_observed_points = ", max_observed_points, " (expected >= ", kMinFitPoints, ")");
  }
  if (max_iterations <= 0) ThrowInvalid(f, "max_iterations = ", max_iterations, " (expected > 0)");
  if (!(transformation_epsilon >= 0)) {
    ThrowInvalid(f, "transformation_epsilon = ", transformation_epsilon, " (expected >= 0)");
  }
  if (!(euclidean_fitness_epsilon >= 0)) {
    ThrowInvalid(f, "euclidean_fitness_epsilon = ", euclidean_fitness_epsilon, " (expected >= 0)");
  }
  if (!(max_correspondence_distance > 0)) {
    ThrowInvalid(f, "max_correspondence_distance = ", max_correspondence_distance, " (expected > 0)");
  }
  if (coarse_points < kMinFitPoints) {
    ThrowInvalid(f, "coarse_points = ", coarse_points, " (expected >= ", kMinFitPoints, ")");
  }
  if (coarse_iterations <= 0) ThrowInvalid(f, "coarse_iterations = ", coarse_iterations, " (expected > 0)");
  if (!(visible_distance > 0)) ThrowInvalid(f, "visible_distance = ", visible_distance, " (expected > 0)");
  if (visible_rounds < 0) ThrowInvalid(f, "visible_rounds = ", visible_rounds, " (expected >= 0)");
  if (!(unexplained_weight >= 0)) {
    ThrowInvalid(f, "unexplained_weight = ", unexplained_weight, " (expected >= 0)");
  }
}

void RecognitionOptions::Validate() const {
  fit.Validate();
  if (max_models <= 0) ThrowInvalid("RecognitionOptions::Validate: max_models = ", max_models, " (expected > 0)");
  if (ranking_iterations <= 0) {
    ThrowInvalid("RecognitionOptions::Validate: ranking_iterations = ", ranking_iterations, " (expected > 0)");
  }
  if (!(confidence_scale > 0)) {
    ThrowInvalid("RecognitionOptions::Validate: confidence_scale = ", confidence_scale, " (expected > 0)");
  }
}

struct ModelFitter::Impl {
  std::string name;
  ModelFitOptions options;
  SurfaceSamples samples;
  PrincipalFrame frame;
  Eigen::Vector3d extents = Eigen::Vector3d::Zero();
  Cloud::Ptr target;
  pcl::search::KdTree<Point>::Ptr target_tree;

  // Runs ICP from X_TR_guess (observed R -> model T) and returns the refined X_TR.
  Eigen::Isometry3d RunIcp(const Cloud::Ptr& source, const Eigen::Isometry3d& X_TR_guess,
                           int iterations, bool& converged) const {
    return RunIcpOn(target, target_tree, source, X_TR_guess, iterations, converged);
  }

  Eigen::Isometry3d RunIcpOn(const Cloud::Ptr& model, const pcl::search::KdTree<Point>::Ptr& model_tree,
                             const Cloud::Ptr& source, const Eigen::Isometry3d& X_TR_guess, int iterations,
                             bool& converged) const {
    pcl::IterativeClosestPoint<Point, Point> icp;
    if (options.metric == IcpMetric::kPointToPlane) icp.setTransformationEstimation(std::make_shared<DampedPointToPlane>());
    icp.setInputSource(source);
    icp.setInputTarget(model);
    // The tree over the model is built once; force_no_recompute keeps ICP from rebuilding it
    // on every call.
    icp.setSearchMethodTarget(model_tree, true);
    icp.setMaximumIterations(iterations);
    icp.setTransformationEpsilon(options.transformation_epsilon);
    icp.setEuclideanFitnessEpsilon(options.euclidean_fitness_epsilon);
    icp.setMaxCorrespondenceDistance(options.max_correspondence_distance);
    Cloud aligned;
    icp.align(aligned, X_TR_guess.matrix().cast<float>());
    converged = icp.hasConverged();
    Eigen::Isometry3d X_TR(icp.getFinalTransformation().cast<double>());
    const auto usable = [](const Eigen::Isometry3d& X) {
      return X.matrix().allFinite() && std::abs(X.linear().determinant() - 1.0) < 0.1;
    };
    if (!usable(X_TR)) {
      converged = false;
      return X_TR_guess;
    }
    // Re-orthonormalise: the float composition drifts slightly from a rotation.
    const Eigen::Quaterniond q(X_TR.rotation());
    X_TR.linear() = q.normalized().toRotationMatrix();
    return X_TR;
  }

  // Mean observed -> model distance for X_RT, and the unexplained visible model fraction.
  void Score(const Eigen::Matrix3Xf& observed, const pcl::KdTreeFLANN<Point>* observed_tree,
             const std::optional<Eigen::Vector3d>& p_R_camera, const Eigen::Isometry3d& X_RT,
             double& fit_error, double& unexplained) const {
    const Eigen::Isometry3d X_TR = X_RT.inverse();
    std::vector<int> index(1);
    std::vector<float> sq_distance(1);
    double sum = 0.0;
    for (Eigen::Index i = 0; i < observed.cols(); ++i) {
      const Eigen::Vector3d p_T = X_TR * observed.col(i).cast<double>();
      target_tree->nearestKSearch(MakePoint(p_T), 1, index, sq_distance);
      sum += std::sqrt(static_cast<double>(sq_distance[0]));
    }
    fit_error = sum / static_cast<double>(observed.cols());
    unexplained = 0.0;
    if (!p_R_camera || observed_tree == nullptr) return;
    int visible = 0;
    int missing = 0;
    const double limit_sq = options.visible_distance * options.visible_distance;
    for (Eigen::Index i = 0; i < samples.points.cols(); ++i) {
      const Eigen::Vector3d p = X_RT * samples.points.col(i).cast<double>();
      const Eigen::Vector3d n = X_RT.linear() * samples.normals.col(i).cast<double>();
      if (n.dot(*p_R_camera - p) <= 0) continue;
      ++visible;
      observed_tree->nearestKSearch(MakePoint(p), 1, index, sq_distance);
      if (sq_distance[0] > limit_sq) ++missing;
    }
    unexplained = visible > 0 ? static_cast<double>(missing) / visible : 0.0;
  }
};

ModelFitter::ModelFitter(const toollib::ToolModel& model, const ModelFitOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  pcl::console::setVerbosityLevel(pcl::console::L_ERROR);
  impl_->name = model.name;
  impl_->options = options;
  impl_->samples = SampleSurface(model.mesh, options.model_points, options.sample_seed);
  impl_->frame = ComputePrincipalFrame(impl_->samples.points);
  impl_->extents = ExtentsAlong(impl_->samples.points, impl_->frame);
  impl_->target = ToPcl(impl_->samples.points, &impl_->samples.normals);
  impl_->target_tree = std::make_shared<pcl::search::KdTree<Point>>();
  impl_->target_tree->setInputCloud(impl_->target);
}

ModelFitter::~ModelFitter() = default;
ModelFitter::ModelFitter(ModelFitter&&) noexcept = default;
ModelFitter& ModelFitter::operator=(ModelFitter&&) noexcept = default;

const SurfaceSamples& ModelFitter::samples() const { return impl_->samples; }
const std::string& ModelFitter::name() const { return impl_->name; }
const Eigen::Vector3d& ModelFitter::principal_extents() const { return impl_->extents; }

ModelFitResult ModelFitter::Fit(const Eigen::Matrix3Xf& p_R,
                                const std::optional<Eigen::Vector3d>& p_R_camera) const {
  RequireFinite(p_R, "ModelFitter::Fit");
  ModelFitResult result;
  result.model = impl_->name;
  if (p_R.cols() < kMinFitPoints) {
    result.status = FitStatus::kTooFewPoints;
    result.reason = Cat("observed cloud has ", p_R.cols(), " points (need >= ", kMinFitPoints, ")");
    return result;
  }
  const ModelFitOptions& options = impl_->options;
  const Eigen::Matrix3Xf observed = EvenSubsample(p_R, options.max_observed_points);
  const Cloud::Ptr source = ToPcl(observed);
  // The candidates only need ranking: a sparser cloud does it at a fraction of the cost.
  const Eigen::Matrix3Xf coarse = EvenSubsample(observed, options.coarse_points);
  const Cloud::Ptr coarse_source = ToPcl(coarse);
  pcl::KdTreeFLANN<Point> observed_tree;
  if (p_R_camera) observed_tree.setInputCloud(ToPcl(p_R));

  // Principal axes of the observation mapped onto the model's: R_RT m_i = o_i.
  const PrincipalFrame seen = ComputePrincipalFrame(observed);
  const PrincipalFrame& model = impl_->frame;
  std::vector<std::pair<std::string, Eigen::Matrix3d>> turns;  // in the model's principal frame
  for (int reversed = 0; reversed < 2; ++reversed) {
    for (int quarter = 0; quarter < 4; ++quarter) {
      if (!options.try_flips && (reversed != 0 || quarter != 0)) continue;
      Eigen::Matrix3d turn =
          Eigen::AngleAxisd(quarter * M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
      if (reversed != 0) turn = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix() * turn;
      turns.emplace_back(Cat(reversed != 0 ? "rev_" : "main_", quarter * 90), turn);
    }
  }
  double best_score = std::numeric_limits<double>::infinity();
  for (const auto& [label, turn] : turns) {
    FitCandidate candidate;
    candidate.label = label;
    // X_RT maps model point p_T to seen.axes * turn * model.axes^T (p_T - c_M) + c_O.
    candidate.X_RT_initial.linear() = seen.axes * turn * model.axes.transpose();
    candidate.X_RT_initial.translation() = seen.centroid - candidate.X_RT_initial.linear() * model.centroid;
    const Eigen::Isometry3d X_TR =
        impl_->RunIcp(coarse_source, candidate.X_RT_initial.inverse(), options.coarse_iterations, candidate.converged);
    candidate.X_RT = X_TR.inverse();
    impl_->Score(coarse, p_R_camera ? &observed_tree : nullptr, p_R_camera, candidate.X_RT, candidate.fit_error,
                 candidate.unexplained);
    candidate.score = candidate.fit_error + options.unexplained_weight * candidate.unexplained;
    if (candidate.score < best_score) {
      best_score = candidate.score;
      result.best_candidate = static_cast<int>(result.candidates.size());
    }
    result.candidates.push_back(std::move(candidate));
  }
  TOOLBENCH_DEMAND(result.best_candidate >= 0);

  const FitCandidate& best = result.candidates[static_cast<std::size_t>(result.best_candidate)];
  result.X_RT = best.X_RT;
  if (!p_R_camera || options.visible_rounds == 0) {
    result.X_RT = impl_->RunIcp(source, best.X_RT.inverse(), options.max_iterations, result.converged).inverse();
  }
  // With the camera known, only the camera-facing model surface can have produced the points.
  // Matching against both faces lets a thin blade's far face pull the fit by its thickness,
  // so the final fit runs against the samples visible at the current pose, re-selected each round.
  for (int round = 0; round < options.visible_rounds && p_R_camera; ++round) {
    const Eigen::Vector3d p_T_camera = result.X_RT.inverse() * *p_R_camera;
    std::vector<Eigen::Index> visible;
    for (Eigen::Index i = 0; i < impl_->samples.points.cols(); ++i) {
      const Eigen::Vector3d p = impl_->samples.points.col(i).cast<double>();
      if (impl_->samples.normals.col(i).cast<double>().dot(p_T_camera - p) > 0) visible.push_back(i);
    }
    if (static_cast<Eigen::Index>(visible.size()) < kMinFitPoints) break;
    Eigen::Matrix3Xf points(3, static_cast<Eigen::Index>(visible.size()));
    Eigen::Matrix3Xf normals(3, static_cast<Eigen::Index>(visible.size()));
    for (std::size_t k = 0; k < visible.size(); ++k) {
      points.col(static_cast<Eigen::Index>(k)) = impl_->samples.points.col(visible[k]);
      normals.col(static_cast<Eigen::Index>(k)) = impl_->samples.normals.col(visible[k]);
    }
    const Cloud::Ptr visible_model = ToPcl(points, &normals);
    auto visible_tree = std::make_shared<pcl::search::KdTree<Point>>();
    visible_tree->setInputCloud(visible_model);
    result.X_RT = impl_->RunIcpOn(visible_model, visible_tree, source, result.X_RT.inverse(), options.max_iterations,
                                  result.converged)
                      .inverse();
  }
  result.iterations = options.max_iterations;
  impl_->Score(observed, p_R_camera ? &observed_tree : nullptr, p_R_camera, result.X_RT, result.fit_error,
               result.unexplained);
  result.score = result.fit_error + options.unexplained_weight * result.unexplained;
  result.status = FitStatus::kOk;
  internal::Logger()->debug("fit {}: best {} error {:.4f} m unexplained {:.3f}", impl_->name, best.label,
                            result.fit_error, result.unexplained);
  return result;
}

struct ToolRecognizer::Impl {
  RecognitionOptions options;
  std::vector<ModelFitter> fitters;   // full options
  std::vector<ModelFitter> rankers;   // same samples, short ICP
};

ToolRecognizer::ToolRecognizer(const std::vector<toollib::ToolModel>& library, const RecognitionOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  if (library.empty()) ThrowInvalid("ToolRecognizer: argument library is empty (expected >= 1 model)");
  impl_->options = options;
  impl_->fitters.reserve(library.size());
  ModelFitOptions ranking = options.fit;
  ranking.max_iterations = options.ranking_iterations;
  for (const toollib::ToolModel& model : library) {
    impl_->fitters.emplace_back(model, options.fit);
    impl_->rankers.emplace_back(model, ranking);
  }
}

ToolRecognizer::~ToolRecognizer() = default;
ToolRecognizer::ToolRecognizer(ToolRecognizer&&) noexcept = default;
ToolRecognizer& ToolRecognizer::operator=(ToolRecognizer&&) noexcept = default;

const ModelFitter& ToolRecognizer::fitter(int index) const {
  if (index < 0 || index >= static_cast<int>(impl_->fitters.size())) {
    ThrowInvalid("ToolRecognizer::fitter: index ", index, " outside [0, ", impl_->fitters.size(), ")");
  }
  return impl_->fitters[static_cast<std::size_t>(index)];
}

RecognitionResult ToolRecognizer::Recognize(const Eigen::Matrix3Xf& p_R,
                                            const std::optional<Eigen::Vector3d>& p_R_camera) const {
  RequireFinite(p_R, "ToolRecognizer::Recognize");
  RecognitionResult result;
  if (p_R.cols() < kMinFitPoints) {
    result.reason = Cat("observed cloud has ", p_R.cols(), " points (need >= ", kMinFitPoints, ")");
    return result;
  }
  const Eigen::Vector3d seen = PrincipalExtents(p_R);
  const std::size_t n = impl_->fitters.size();
  result.scores.resize(n);
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& model = impl_->fitters[i].principal_extents();
    ModelScore& s = result.scores[i];
    s.model = impl_->fitters[i].name();
    // Occlusion can shorten the observed length, so a shorter observation costs half as much as
    // a longer one. The width depends on the view (a blade seen edge-on looks thin), so it
    // counts a quarter.
    const double length_ratio = (seen.x() - model.x()) / model.x();
    const double width_ratio = (seen.y() - model.y()) / std::max(model.y(), 1e-3);
    s.extent_distance = (length_ratio > 0 ? 2.0 : 1.0) * std::abs(length_ratio) + 0.25 * std::abs(width_ratio);
    order[i] = i;
  }
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return result.scores[a].extent_distance < result.scores[b].extent_distance;
  });
  const std::size_t fitted = std::min<std::size_t>(n, static_cast<std::size_t>(impl_->options.max_models));
  double best_score = std::numeric_limits<double>::infinity();
  std::size_t best = order[0];
  for (std::size_t k = 0; k < fitted; ++k) {
    const std::size_t i = order[k];
    ModelScore& s = result.scores[i];
    s.fitted = true;
    s.score = impl_->rankers[i].Fit(p_R, p_R_camera).score;
    if (s.score < best_score) {
      best_score = s.score;
      best = i;
    }
  }
  result.fit = impl_->fitters[best].Fit(p_R, p_R_camera);
  double normaliser = 0.0;
  for (const ModelScore& s : result.scores) {
    if (s.fitted) normaliser += std::exp(-(s.score - best_score) / impl_->options.confidence_scale);
  }
  result.status = FitStatus::kOk;
  result.model = result.fit.model;
  result.confidence = 1.0 / normaliser;
  internal::Logger()->debug("recognised {} (confidence {:.2f}, score {:.4f} m)", result.model, result.confidence,
                            best_score);
  return result;
}

}  // namespace toolbench::perception
