#include "perception/model_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include <Eigen/Eigenvalues>
#include <pcl/console/print.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/correspondence_estimation.h>
#include <pcl/registration/icp.h>
#include <pcl/registration/transformation_estimation.h>
#include <pcl/search/kdtree.h>
#include <spdlog/spdlog.h>

#include "common/check.h"
#include "common/rng.h"
#include "perception/internal/log.h"
#include "perception/internal/nearest_neighbours.h"

namespace toolbench::perception {
namespace {

using Point = pcl::PointNormal;
using Cloud = pcl::PointCloud<Point>;

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

// pcl::registration::CorrespondenceEstimation with each iteration's nearest-neighbour queries
// asked as one batch of internal::NearestNeighbours (the same tree and answers as the
// pcl::search::KdTree it replaces, without FLANN's per-query overhead): the same pairs in the same
// order, so pcl::IterativeClosestPoint takes the same steps. The ICP's own search tree is never
// built (it is set with force_no_recompute, RunIcpOn).
class BatchedCorrespondences : public pcl::registration::CorrespondenceEstimation<Point, Point, float> {
 public:
  explicit BatchedCorrespondences(internal::NearestNeighbours target) : target_nn_(std::move(target)) {}

  void determineCorrespondences(pcl::Correspondences& correspondences, double max_distance) override {
    // PCLBase's part of initCompute (the source indices); the base class's would build tree_.
    if (!pcl::PCLBase<Point>::initCompute()) return;
    const pcl::Indices& indices = *indices_;
    queries_.resize(3, static_cast<Eigen::Index>(indices.size()));
    for (std::size_t k = 0; k < indices.size(); ++k) {
      queries_.col(static_cast<Eigen::Index>(k)) = (*input_)[static_cast<std::size_t>(indices[k])].getVector3fMap();
    }
    target_nn_.Find(queries_, match_, sq_distance_);
    const double max_sq = max_distance * max_distance;
    correspondences.clear();
    for (std::size_t k = 0; k < indices.size(); ++k) {
      if (sq_distance_[k] > max_sq) continue;
      correspondences.emplace_back(indices[k], match_[k], sq_distance_[k]);
    }
    deinitCompute();
  }

  void determineReciprocalCorrespondences(pcl::Correspondences& /*correspondences*/, double /*max_distance*/) override {
    ThrowInvalid("BatchedCorrespondences: reciprocal correspondences are not supported");
  }

  pcl::registration::CorrespondenceEstimationBase<Point, Point, float>::Ptr clone() const override {
    return std::make_shared<BatchedCorrespondences>(*this);
  }

 private:
  internal::NearestNeighbours target_nn_;
  Eigen::Matrix3Xf queries_;
  std::vector<int> match_;
  std::vector<float> sq_distance_;
};

constexpr int kStallIterations = 10;
constexpr double kStallImprovement = 1e-4;  // relative MSE improvement that counts as progress

struct IcpLimits {
  int iterations = 1;
  double max_correspondence_distance = 0.05;
  double transformation_epsilon = 1e-9;
  double euclidean_fitness_epsilon = 1e-6;
};

// Damped point-to-plane ICP (linearised rotation, as PCL's TransformationEstimationPointToPlaneLLS)
// of `source` (observed points) onto `model` (points with unit normals), starting from X_TR.
// Written out instead of pcl::IterativeClosestPoint because ICP is the whole cost of recognition
// and PCL's loop copies and transforms the source cloud, allocates correspondence vectors and
// runs a rejector every iteration: this loop transforms the points, asks their nearest model
// points as one batch and accumulates the step, nothing else (2-3x faster on the few hundred
// points ranking uses, measured when both asked one point at a time). The small Levenberg
// damping matters: PCL's LLS inverts the 6x6 normal matrix outright, which is singular for a
// shape symmetric about an axis (a stick's spin is unobservable) and returns NaN; damping leaves
// the unobservable direction unchanged instead. Stopping rules follow PCL's
// DefaultConvergenceCriteria as pcl::IterativeClosestPoint sets them up: the iteration cap; a
// step with squared translation <= transformation_epsilon [m^2] and rotation cosine >=
// 1 - transformation_epsilon; or a relative change of the mean squared correspondence distance
// below euclidean_fitness_epsilon (PCL's absolute threshold, 1e-12 m^2, is never the binding one).
// The step is linearised about `p_T_centre` (the model's centroid), not about the frame origin:
// the tool frame's origin is at one end of the tool, and rotations about a far point couple with
// translations, which made the damped step crawl for hundreds of iterations.
Eigen::Isometry3d PointToPlaneIcp(const Cloud& source, const Cloud& model, const internal::NearestNeighbours& model_nn,
                                  const Eigen::Vector3d& p_T_centre, Eigen::Isometry3d X_TR, const IcpLimits& limits,
                                  bool& converged) {
  converged = false;
  std::vector<int> index;
  std::vector<float> sq_distance;
  Eigen::Matrix3Xf queries(3, static_cast<Eigen::Index>(source.size()));
  const float max_sq = static_cast<float>(limits.max_correspondence_distance * limits.max_correspondence_distance);
  double previous_mse = std::numeric_limits<double>::infinity();
  double best_mse = std::numeric_limits<double>::infinity();
  int stalled = 0;  // iterations since the MSE last improved by kStallImprovement
  for (int iteration = 0; iteration < limits.iterations; ++iteration) {
    const Eigen::Matrix3f R = X_TR.linear().cast<float>();
    const Eigen::Vector3f t = X_TR.translation().cast<float>();
    Eigen::Matrix<double, 6, 6> AtA = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> Atb = Eigen::Matrix<double, 6, 1>::Zero();
    double sum_sq = 0.0;
    int pairs = 0;
    for (std::size_t k = 0; k < source.size(); ++k) {
      queries.col(static_cast<Eigen::Index>(k)) = R * source[k].getVector3fMap() + t;
    }
    model_nn.Find(queries, index, sq_distance);
    for (std::size_t k = 0; k < source.size(); ++k) {
      if (sq_distance[k] > max_sq) continue;
      const Point& m = model[static_cast<std::size_t>(index[k])];
      const Eigen::Vector3d p = queries.col(static_cast<Eigen::Index>(k)).cast<double>() - p_T_centre;
      const Eigen::Vector3d n = m.getNormalVector3fMap().cast<double>();
      Eigen::Matrix<double, 6, 1> a;
      a << p.cross(n), n;
      AtA.selfadjointView<Eigen::Upper>().rankUpdate(a);
      Atb += a * n.dot(m.getVector3fMap().cast<double>() - p_T_centre - p);
      sum_sq += sq_distance[k];
      ++pairs;
    }
    if (pairs < 6) break;  // too few correspondences: keep the pose (PCL gives up the same way)
    AtA.triangularView<Eigen::Lower>() = AtA.transpose();
    const double damping = 1e-4 * AtA.trace() / 6.0 + 1e-12;
    AtA.diagonal().array() += damping;
    const Eigen::Matrix<double, 6, 1> x = AtA.ldlt().solve(Atb);
    if (!x.allFinite()) break;
    Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
    const Eigen::Vector3d omega = x.head<3>();
    if (omega.norm() > 0) step.linear() = Eigen::AngleAxisd(omega.norm(), omega.normalized()).toRotationMatrix();
    // Rotation about the centre c, then translation: p -> R (p - c) + c + t.
    step.translation() = p_T_centre - step.linear() * p_T_centre + x.tail<3>();
    X_TR = step * X_TR;
    const double mse = sum_sq / pairs;
    const double cosine = (step.linear().trace() - 1.0) / 2.0;
    if ((cosine >= 1.0 - limits.transformation_epsilon &&
         step.translation().squaredNorm() <= limits.transformation_epsilon) ||
        std::abs(mse - previous_mse) < 1e-12 ||
        std::abs(mse - previous_mse) < limits.euclidean_fitness_epsilon * previous_mse) {
      converged = true;
      break;
    }
    // Correspondences that flip between a thin blade's two faces make the pose oscillate by a
    // fraction of a degree with the MSE jittering above PCL's relative threshold until the cap;
    // no real progress for kStallIterations iterations ends the loop too.
    if (mse < best_mse * (1.0 - kStallImprovement)) {
      best_mse = mse;
      stalled = 0;
    } else if (++stalled >= kStallIterations) {
      converged = true;
      break;
    }
    previous_mse = mse;
  }
  return X_TR;
}

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

void RequireView(const std::optional<FitView>& view, const char* function) {
  if (!view) return;
  if (view->depth.empty() || view->depth.type() != CV_32FC1) {
    ThrowInvalid(function, ": argument view.depth is ", view->depth.empty() ? "empty" : "not CV_32FC1",
                 " (expected a CV_32FC1 depth image)");
  }
  if (view->mask.type() != CV_8UC1 || view->mask.size() != view->depth.size()) {
    ThrowInvalid(function, ": argument view.mask is ", view->mask.cols, "x", view->mask.rows, " of type ",
                 view->mask.type(), " (expected CV_8UC1 of the depth's size ", view->depth.cols, "x", view->depth.rows,
                 ")");
  }
  const CameraIntrinsics& k = view->intrinsics;
  if (k.width != view->depth.cols || k.height != view->depth.rows || !(k.fx > 0) || !(k.fy > 0)) {
    ThrowInvalid(function, ": argument view.intrinsics is ", k.width, "x", k.height, " fx ", k.fx, " fy ", k.fy,
                 " (expected the depth's size ", view->depth.cols, "x", view->depth.rows,
                 " and positive focal lengths)");
  }
  if (!view->X_RC.matrix().allFinite()) ThrowInvalid(function, ": argument view.X_RC is not finite");
}

// Rigid motion of T onto itself: rotation by `angle` about the line through `pivot` along `axis`.
Eigen::Isometry3d TurnAbout(const Eigen::Vector3d& pivot, const Eigen::Vector3d& axis, double angle) {
  Eigen::Isometry3d M = Eigen::Isometry3d::Identity();
  M.linear() = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
  M.translation() = pivot - M.linear() * pivot;
  return M;
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
  if (screen_iterations < 0) ThrowInvalid(f, "screen_iterations = ", screen_iterations, " (expected >= 0)");
  if (screen_keep <= 0) ThrowInvalid(f, "screen_keep = ", screen_keep, " (expected > 0)");
  if (spin_steps < 1 || spin_steps > 36) ThrowInvalid(f, "spin_steps = ", spin_steps, " (expected in [1, 36])");
  if (!(visible_distance > 0)) ThrowInvalid(f, "visible_distance = ", visible_distance, " (expected > 0)");
  if (visible_rounds < 0) ThrowInvalid(f, "visible_rounds = ", visible_rounds, " (expected >= 0)");
  if (!(unexplained_weight >= 0)) {
    ThrowInvalid(f, "unexplained_weight = ", unexplained_weight, " (expected >= 0)");
  }
  if (score_model_points < kMinFitPoints) {
    ThrowInvalid(f, "score_model_points = ", score_model_points, " (expected >= ", kMinFitPoints, ")");
  }
  if (view_spin_steps < 0 || view_spin_steps > 72) {
    ThrowInvalid(f, "view_spin_steps = ", view_spin_steps, " (expected in [0, 72])");
  }
  if (view_points < kMinFitPoints) {
    ThrowInvalid(f, "view_points = ", view_points, " (expected >= ", kMinFitPoints, ")");
  }
  if (view_refine_points < kMinFitPoints) {
    ThrowInvalid(f, "view_refine_points = ", view_refine_points, " (expected >= ", kMinFitPoints, ")");
  }
  if (view_keep <= 0) ThrowInvalid(f, "view_keep = ", view_keep, " (expected > 0)");
  if (view_iterations <= 0) ThrowInvalid(f, "view_iterations = ", view_iterations, " (expected > 0)");
  if (!(view_free_distance > 0)) ThrowInvalid(f, "view_free_distance = ", view_free_distance, " (expected > 0)");
  if (!(view_weight >= 0)) ThrowInvalid(f, "view_weight = ", view_weight, " (expected >= 0)");
}

void RecognitionOptions::Validate() const {
  fit.Validate();
  if (max_models <= 0) ThrowInvalid("RecognitionOptions::Validate: max_models = ", max_models, " (expected > 0)");
  if (verify_points < kMinFitPoints) {
    ThrowInvalid("RecognitionOptions::Validate: verify_points = ", verify_points, " (expected >= ", kMinFitPoints, ")");
  }
  if (verify_iterations <= 0) {
    ThrowInvalid("RecognitionOptions::Validate: verify_iterations = ", verify_iterations, " (expected > 0)");
  }
  if (max_classifier_candidates <= 0) {
    ThrowInvalid("RecognitionOptions::Validate: max_classifier_candidates = ", max_classifier_candidates,
                 " (expected > 0)");
  }
  if (!(min_classifier_probability >= 0 && min_classifier_probability < 1)) {
    ThrowInvalid("RecognitionOptions::Validate: min_classifier_probability = ", min_classifier_probability,
                 " (expected in [0, 1))");
  }
  if (!(classifier_mass > 0 && classifier_mass <= 1)) {
    ThrowInvalid("RecognitionOptions::Validate: classifier_mass = ", classifier_mass, " (expected in (0, 1])");
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
  internal::NearestNeighbours target_nn;
  SurfaceSamples score_samples;  // evenly picked subset of `samples` for the unexplained fraction
  Eigen::Vector3d handle_axis_T = Eigen::Vector3d::UnitZ();   // unit; the view check turns about it
  Eigen::Vector3d handle_centre_T = Eigen::Vector3d::Zero();  // a point on that axis [m]
  Eigen::Vector3d flip_pivot_T = Eigen::Vector3d::Zero();     // middle of the samples along the axis [m]
  Eigen::Vector3d flip_axis_T = Eigen::Vector3d::UnitX();     // unit, perpendicular to the handle axis

  // The observed cloud in the forms a fit uses, built once per Search or Refine.
  struct Observation {
    Eigen::Matrix3Xf observed;     // at most max_observed_points
    Cloud::Ptr source;
    Eigen::Matrix3Xf coarse;       // at most coarse_points
    Cloud::Ptr coarse_source;
    internal::NearestNeighbours observed_nn;  // over `observed`, only with a camera
  };

  void Observe(const Eigen::Matrix3Xf& p_R, bool with_camera, int max_points, Observation& o) const {
    o.observed = EvenSubsample(p_R, max_points);
    o.source = ToPcl(o.observed);
    // The candidates only need ranking: a sparser cloud does it at a fraction of the cost.
    o.coarse = EvenSubsample(o.observed, options.coarse_points);
    o.coarse_source = ToPcl(o.coarse);
    // The unexplained test asks "is any observed point within visible_distance (1 cm)": the
    // subsampled cloud (spacing a few mm) answers it as well as the full one, at a lower cost.
    if (with_camera) o.observed_nn = internal::NearestNeighbours(o.observed);
  }

  // Runs ICP from X_TR_guess (observed R -> model T) and returns the refined X_TR.
  Eigen::Isometry3d RunIcp(const Cloud::Ptr& source, const Eigen::Isometry3d& X_TR_guess,
                           int iterations, bool own_loop, bool& converged) const {
    return RunIcpOn(target, target_nn, source, X_TR_guess, iterations, own_loop, converged);
  }

  Eigen::Isometry3d RunIcpOn(const Cloud::Ptr& model, const internal::NearestNeighbours& model_nn,
                             const Cloud::Ptr& source, const Eigen::Isometry3d& X_TR_guess, int iterations,
                             bool own_loop, bool& converged) const {
    Eigen::Isometry3d X_TR = X_TR_guess;
    if (options.metric == IcpMetric::kPointToPlane && own_loop) {
      IcpLimits limits;
      limits.iterations = iterations;
      limits.max_correspondence_distance = options.max_correspondence_distance;
      limits.transformation_epsilon = options.transformation_epsilon;
      limits.euclidean_fitness_epsilon = options.euclidean_fitness_epsilon;
      X_TR = PointToPlaneIcp(*source, *model, model_nn, frame.centroid, X_TR_guess, limits, converged);
    } else {
      // PCL's ICP: the thesis's point-to-point baseline, and the final point-to-plane refinement
      // (PCL's loop converged to better poses on thin blades in our tests; it runs once per tool).
      pcl::IterativeClosestPoint<Point, Point> icp;
      if (options.metric == IcpMetric::kPointToPlane) icp.setTransformationEstimation(std::make_shared<DampedPointToPlane>());
      icp.setCorrespondenceEstimation(std::make_shared<BatchedCorrespondences>(model_nn));
      icp.setInputSource(source);
      icp.setInputTarget(model);
      // The correspondences search model_nn (built once per model); force_no_recompute keeps
      // the ICP from building a kd-tree of its own that nothing would use.
      icp.setSearchMethodTarget(std::make_shared<pcl::search::KdTree<Point>>(), true);
      icp.setMaximumIterations(iterations);
      icp.setTransformationEpsilon(options.transformation_epsilon);
      icp.setEuclideanFitnessEpsilon(options.euclidean_fitness_epsilon);
      icp.setMaxCorrespondenceDistance(options.max_correspondence_distance);
      Cloud aligned;
      icp.align(aligned, X_TR_guess.matrix().cast<float>());
      converged = icp.hasConverged();
      X_TR = Eigen::Isometry3d(icp.getFinalTransformation().cast<double>());
    }
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
  void Score(const Eigen::Matrix3Xf& observed, const internal::NearestNeighbours* observed_nn,
             const std::optional<Eigen::Vector3d>& p_R_camera, const Eigen::Isometry3d& X_RT,
             const SurfaceSamples& model_samples, double& fit_error, double& unexplained) const {
    const Eigen::Isometry3d X_TR = X_RT.inverse();
    Eigen::Matrix3Xf queries(3, observed.cols());
    for (Eigen::Index i = 0; i < observed.cols(); ++i) {
      queries.col(i) = (X_TR * observed.col(i).cast<double>()).cast<float>();
    }
    fit_error = MeanDistanceToModel(queries);
    unexplained = 0.0;
    if (!p_R_camera || observed_nn == nullptr) return;
    const double limit_sq = options.visible_distance * options.visible_distance;
    queries.resize(3, model_samples.points.cols());
    Eigen::Index visible = 0;
    for (Eigen::Index i = 0; i < model_samples.points.cols(); ++i) {
      const Eigen::Vector3d p = X_RT * model_samples.points.col(i).cast<double>();
      const Eigen::Vector3d n = X_RT.linear() * model_samples.normals.col(i).cast<double>();
      if (n.dot(*p_R_camera - p) <= 0) continue;
      queries.col(visible++) = p.cast<float>();
    }
    std::vector<int> index;
    std::vector<float> sq_distance;
    observed_nn->Find(queries.leftCols(visible), index, sq_distance);
    const auto missing = std::count_if(sq_distance.begin(), sq_distance.end(), [&](float d) { return d > limit_sq; });
    unexplained = visible > 0 ? static_cast<double>(missing) / static_cast<double>(visible) : 0.0;
  }

  // Mean distance observed point -> nearest model point for X_RT [m].
  double MeanDistance(const Eigen::Matrix3Xf& observed, const Eigen::Isometry3d& X_RT) const {
    const Eigen::Isometry3f X_TR = X_RT.inverse().cast<float>();
    Eigen::Matrix3Xf queries(3, observed.cols());
    for (Eigen::Index i = 0; i < observed.cols(); ++i) queries.col(i) = X_TR * Eigen::Vector3f(observed.col(i));
    return MeanDistanceToModel(queries);
  }

  // Mean distance from points in T (3 x N) to their nearest model samples [m]; 0 for no points.
  double MeanDistanceToModel(const Eigen::Matrix3Xf& p_T) const {
    std::vector<int> index;
    std::vector<float> sq_distance;
    target_nn.Find(p_T, index, sq_distance);
    double sum = 0.0;
    for (const float d : sq_distance) sum += std::sqrt(static_cast<double>(d));
    return sum / static_cast<double>(std::max<Eigen::Index>(p_T.cols(), 1));
  }

  // Fraction of the camera-facing samples that the depth image contradicts at pose X_RT: the
  // camera saw through them (observed depth clearly behind the predicted one) or they fall
  // outside the tool's mask with nothing nearer hiding them. Samples hidden by a nearer observed
  // surface (the tool's own far side, another tool) or outside the image are neutral: the image
  // says nothing about them; inside the mask a missing return is a dropout, also neutral.
  double ViewViolation(const FitView& view, const Eigen::Isometry3d& X_RT, const SurfaceSamples& model) const {
    const Eigen::Isometry3d X_CT = view.X_RC.inverse() * X_RT;
    const Eigen::Matrix3f R = X_CT.linear().cast<float>();
    const Eigen::Vector3f t = X_CT.translation().cast<float>();
    const Eigen::Vector3f p_T_camera = X_CT.inverse().translation().cast<float>();
    const CameraIntrinsics& k = view.intrinsics;
    const float free = static_cast<float>(options.view_free_distance);
    int facing = 0;
    int violated = 0;
    for (Eigen::Index i = 0; i < model.points.cols(); ++i) {
      const Eigen::Vector3f p_T = model.points.col(i);
      if (model.normals.col(i).dot(p_T_camera - p_T) <= 0) continue;
      const Eigen::Vector3f p_C = R * p_T + t;
      if (p_C.z() <= 1e-3f) continue;
      const long u = std::lround(k.fx * p_C.x() / p_C.z() + k.cx);
      const long v = std::lround(k.fy * p_C.y() / p_C.z() + k.cy);
      if (u < 0 || v < 0 || u >= view.depth.cols || v >= view.depth.rows) continue;
      const float d = view.depth.at<float>(static_cast<int>(v), static_cast<int>(u));
      const bool in_mask = view.mask.at<std::uint8_t>(static_cast<int>(v), static_cast<int>(u)) != 0;
      const bool has_depth = std::isfinite(d) && d > 0.0f;
      ++facing;
      if (has_depth && d < p_C.z() - free) continue;
      if (!in_mask || (has_depth && p_C.z() < d - free)) ++violated;
    }
    return facing > 0 ? static_cast<double>(violated) / facing : 1.0;
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
  impl_->target_nn = internal::NearestNeighbours(impl_->samples.points);
  if (model.handle.axis.norm() > 0) impl_->handle_axis_T = model.handle.axis.normalized();
  impl_->handle_centre_T = model.handle.center;
  const Eigen::VectorXf along = impl_->handle_axis_T.cast<float>().transpose() *
                                (impl_->samples.points.colwise() - impl_->handle_centre_T.cast<float>());
  impl_->flip_pivot_T =
      impl_->handle_centre_T + impl_->handle_axis_T * 0.5 * static_cast<double>(along.minCoeff() + along.maxCoeff());
  impl_->flip_axis_T = impl_->handle_axis_T.unitOrthogonal();
  const Eigen::Index count = std::min<Eigen::Index>(options.score_model_points, impl_->samples.points.cols());
  impl_->score_samples.points.resize(3, count);
  impl_->score_samples.normals.resize(3, count);
  const double stride = static_cast<double>(impl_->samples.points.cols()) / static_cast<double>(count);
  for (Eigen::Index i = 0; i < count; ++i) {
    const auto j = static_cast<Eigen::Index>(static_cast<double>(i) * stride);
    impl_->score_samples.points.col(i) = impl_->samples.points.col(j);
    impl_->score_samples.normals.col(i) = impl_->samples.normals.col(j);
  }
}

ModelFitter::~ModelFitter() = default;
ModelFitter::ModelFitter(ModelFitter&&) noexcept = default;
ModelFitter& ModelFitter::operator=(ModelFitter&&) noexcept = default;

const SurfaceSamples& ModelFitter::samples() const { return impl_->samples; }
const std::string& ModelFitter::name() const { return impl_->name; }
const Eigen::Vector3d& ModelFitter::principal_extents() const { return impl_->extents; }

ModelFitResult ModelFitter::Fit(const Eigen::Matrix3Xf& p_R, const std::optional<Eigen::Vector3d>& p_R_camera,
                                const std::optional<FitView>& view) const {
  RequireView(view, "ModelFitter::Fit");
  ModelFitResult searched = Search(p_R, p_R_camera);
  if (searched.status != FitStatus::kOk) return searched;
  return Refine(p_R, p_R_camera, std::move(searched), view);
}

ModelFitResult ModelFitter::Search(const Eigen::Matrix3Xf& p_R,
                                   const std::optional<Eigen::Vector3d>& p_R_camera) const {
  RequireFinite(p_R, "ModelFitter::Search");
  ModelFitResult result;
  result.model = impl_->name;
  if (p_R.cols() < kMinFitPoints) {
    result.status = FitStatus::kTooFewPoints;
    result.reason = Cat("observed cloud has ", p_R.cols(), " points (need >= ", kMinFitPoints, ")");
    return result;
  }
  const ModelFitOptions& options = impl_->options;
  Impl::Observation o;
  impl_->Observe(p_R, p_R_camera.has_value(), options.max_observed_points, o);

  // Principal axes of the observation mapped onto the model's: R_RT m_i = o_i.
  const PrincipalFrame seen = ComputePrincipalFrame(o.observed);
  const PrincipalFrame& model = impl_->frame;
  std::vector<std::pair<std::string, Eigen::Matrix3d>> turns;  // in the model's principal frame
  for (int reversed = 0; reversed < 2; ++reversed) {
    for (int step = 0; step < options.spin_steps; ++step) {
      if (!options.try_flips && (reversed != 0 || step != 0)) continue;
      const int degrees = step * 360 / options.spin_steps;
      Eigen::Matrix3d turn = Eigen::AngleAxisd(degrees * M_PI / 180, Eigen::Vector3d::UnitX()).toRotationMatrix();
      if (reversed != 0) turn = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix() * turn;
      turns.emplace_back(Cat(reversed != 0 ? "rev_" : "main_", degrees), turn);
    }
  }
  const auto score = [&](FitCandidate& candidate) {
    impl_->Score(o.coarse, p_R_camera ? &o.observed_nn : nullptr, p_R_camera, candidate.X_RT, impl_->score_samples,
                 candidate.fit_error, candidate.unexplained);
    candidate.score = candidate.fit_error + options.unexplained_weight * candidate.unexplained;
  };
  // Screening: a few iterations tell the hopeless initial guesses (most of the 8) from the
  // promising ones, which alone get the rest of the coarse iterations.
  const bool screen = options.screen_iterations > 0 && options.screen_iterations < options.coarse_iterations &&
                      static_cast<int>(turns.size()) > options.screen_keep;
  for (const auto& [label, turn] : turns) {
    FitCandidate candidate;
    candidate.label = label;
    // X_RT maps model point p_T to seen.axes * turn * model.axes^T (p_T - c_M) + c_O.
    candidate.X_RT_initial.linear() = seen.axes * turn * model.axes.transpose();
    candidate.X_RT_initial.translation() = seen.centroid - candidate.X_RT_initial.linear() * model.centroid;
    const Eigen::Isometry3d X_TR =
        impl_->RunIcp(o.coarse_source, candidate.X_RT_initial.inverse(),
                      screen ? options.screen_iterations : options.coarse_iterations, true, candidate.converged);
    candidate.X_RT = X_TR.inverse();
    score(candidate);
    result.candidates.push_back(std::move(candidate));
  }
  if (screen) {
    std::vector<std::size_t> order(result.candidates.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return result.candidates[a].score < result.candidates[b].score;
    });
    for (int k = 0; k < options.screen_keep; ++k) {
      FitCandidate& candidate = result.candidates[order[static_cast<std::size_t>(k)]];
      candidate.X_RT = impl_->RunIcp(o.coarse_source, candidate.X_RT.inverse(),
                                     options.coarse_iterations - options.screen_iterations, true, candidate.converged)
                           .inverse();
      score(candidate);
    }
  }
  double best_score = std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < result.candidates.size(); ++k) {
    if (result.candidates[k].score < best_score) {
      best_score = result.candidates[k].score;
      result.best_candidate = static_cast<int>(k);
    }
  }
  TOOLBENCH_DEMAND(result.best_candidate >= 0);
  const FitCandidate& best = result.candidates[static_cast<std::size_t>(result.best_candidate)];
  result.X_RT = best.X_RT;
  result.fit_error = best.fit_error;
  result.unexplained = best.unexplained;
  result.score = best.score;
  result.converged = best.converged;
  result.iterations = options.coarse_iterations;
  result.status = FitStatus::kOk;
  return result;
}

ModelFitResult ModelFitter::Refine(const Eigen::Matrix3Xf& p_R, const std::optional<Eigen::Vector3d>& p_R_camera,
                                   ModelFitResult searched, const std::optional<FitView>& view) const {
  RequireView(view, "ModelFitter::Refine");
  return RefineWith(p_R, p_R_camera, std::move(searched), impl_->options.max_observed_points,
                    impl_->options.max_iterations, false, view ? &*view : nullptr);
}

ModelFitResult ModelFitter::Refine(const Eigen::Matrix3Xf& p_R, const std::optional<Eigen::Vector3d>& p_R_camera,
                                   ModelFitResult searched, int max_observed_points, int max_iterations) const {
  return RefineWith(p_R, p_R_camera, std::move(searched), max_observed_points, max_iterations, true, nullptr);
}

ModelFitResult ModelFitter::RefineWith(const Eigen::Matrix3Xf& p_R, const std::optional<Eigen::Vector3d>& p_R_camera,
                                       ModelFitResult searched, int max_observed_points, int max_iterations,
                                       bool own_loop, const FitView* view) const {
  RequireFinite(p_R, "ModelFitter::Refine");
  if (max_observed_points < kMinFitPoints) {
    ThrowInvalid("ModelFitter::Refine: argument max_observed_points = ", max_observed_points, " (expected >= ",
                 kMinFitPoints, ")");
  }
  if (max_iterations <= 0) {
    ThrowInvalid("ModelFitter::Refine: argument max_iterations = ", max_iterations, " (expected > 0)");
  }
  if (searched.status != FitStatus::kOk || searched.model != impl_->name || searched.best_candidate < 0 ||
      searched.best_candidate >= static_cast<int>(searched.candidates.size())) {
    ThrowInvalid("ModelFitter::Refine: argument searched (model '", searched.model,
                 "') is not a successful Search result of this fitter (model '", impl_->name, "')");
  }
  if (p_R.cols() < kMinFitPoints) {
    ThrowInvalid("ModelFitter::Refine: argument p_R has ", p_R.cols(), " points (expected >= ", kMinFitPoints, ")");
  }
  const ModelFitOptions& options = impl_->options;
  Impl::Observation o;
  impl_->Observe(p_R, p_R_camera.has_value(), max_observed_points, o);
  ModelFitResult result = std::move(searched);
  const FitCandidate& best = result.candidates[static_cast<std::size_t>(result.best_candidate)];
  if (!p_R_camera || options.visible_rounds == 0) {
    result.X_RT =
        impl_->RunIcp(o.source, result.X_RT.inverse(), max_iterations, own_loop, result.converged).inverse();
  }
  // With the camera known, only the camera-facing model surface can have produced the points.
  // Matching against both faces lets a thin blade's far face pull the fit by its thickness,
  // so the final fit runs against the samples visible at the current pose, re-selected each round.
  const auto visible_refine = [&](const Cloud::Ptr& source, int iterations, bool loop) {
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
      const Eigen::Isometry3d X_TR = impl_->RunIcpOn(visible_model, internal::NearestNeighbours(points), source, result.X_RT.inverse(),
                                                     iterations, loop, result.converged);
      result.X_RT = X_TR.inverse();
    }
  };
  visible_refine(o.source, max_iterations, own_loop);
  if (view != nullptr && options.view_spin_steps > 0) {
    // ICP cannot tell a blade seen edge-on from one turned by a few tens of degrees, or a rake's
    // teeth towards the camera from away from it: the points fit both about equally. The depth
    // image can: a wrong turn puts material where the camera saw through to the board, or
    // outside the tool's silhouette. So every turn about the handle axis (and its end-to-end
    // flip) is scored against the image, and the most promising few get a short ICP.
    struct Hypothesis {
      std::string label;
      Eigen::Isometry3d X_RT;
      double cost = 0.0;
    };
    const Eigen::Matrix3Xf ranked = EvenSubsample(o.coarse, options.view_points);
    const auto cost = [&](const Eigen::Isometry3d& X_RT) {
      return impl_->MeanDistance(ranked, X_RT) +
             options.view_weight * impl_->ViewViolation(*view, X_RT, impl_->score_samples);
    };
    std::vector<Hypothesis> hypotheses;
    const Eigen::Isometry3d base = result.X_RT;
    for (int flip = 0; flip < 2; ++flip) {
      for (int step = 0; step < options.view_spin_steps; ++step) {
        const double angle = 2.0 * M_PI * step / options.view_spin_steps;
        Eigen::Isometry3d M = TurnAbout(impl_->handle_centre_T, impl_->handle_axis_T, angle);
        if (flip != 0) M = TurnAbout(impl_->flip_pivot_T, impl_->flip_axis_T, M_PI) * M;
        Hypothesis h;
        h.label = Cat(flip != 0 ? "flip_" : "spin_", std::lround(angle * 180.0 / M_PI));
        h.X_RT = base * M;
        h.cost = cost(h.X_RT);
        hypotheses.push_back(std::move(h));
      }
    }
    std::vector<std::size_t> order(hypotheses.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return hypotheses[a].cost < hypotheses[b].cost; });
    // The ICP result (hypothesis 0) always stays in the race, as it is.
    std::size_t winner = 0;
    for (std::size_t k = 0; k < order.size() && k < static_cast<std::size_t>(options.view_keep); ++k) {
      Hypothesis& h = hypotheses[order[k]];
      if (order[k] != 0) {
        bool converged = false;
        h.X_RT = impl_->RunIcp(o.coarse_source, h.X_RT.inverse(), options.view_iterations, true, converged).inverse();
        h.cost = cost(h.X_RT);
      }
      if (h.cost < hypotheses[winner].cost) winner = order[k];
    }
    internal::Logger()->debug("fit {}: view check keeps {} (cost {:.4f} m; ICP result {:.4f} m)", impl_->name,
                              hypotheses[winner].label, hypotheses[winner].cost, hypotheses[0].cost);
    result.view_turn = hypotheses[winner].label;
    if (winner != 0) {
      result.X_RT = hypotheses[winner].X_RT;
      // A short refinement on a subset: the turn is settled, the few mm left need no 2000 points.
      visible_refine(ToPcl(EvenSubsample(o.observed, options.view_refine_points)), options.view_iterations, true);
    }
    result.violation = impl_->ViewViolation(*view, result.X_RT, impl_->samples);
  }
  result.iterations = max_iterations;
  impl_->Score(o.observed, p_R_camera ? &o.observed_nn : nullptr, p_R_camera, result.X_RT, impl_->samples, result.fit_error,
               result.unexplained);
  result.score = result.fit_error + options.unexplained_weight * result.unexplained;
  result.status = FitStatus::kOk;
  internal::Logger()->debug("fit {}: best {} error {:.4f} m unexplained {:.3f}", impl_->name, best.label,
                            result.fit_error, result.unexplained);
  return result;
}

struct ToolRecognizer::Impl {
  RecognitionOptions options;
  std::vector<ModelFitter> fitters;
};

ToolRecognizer::ToolRecognizer(const std::vector<toollib::ToolModel>& library, const RecognitionOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.Validate();
  if (library.empty()) ThrowInvalid("ToolRecognizer: argument library is empty (expected >= 1 model)");
  impl_->options = options;
  impl_->fitters.reserve(library.size());
  for (const toollib::ToolModel& model : library) impl_->fitters.emplace_back(model, options.fit);
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

std::vector<std::string> ToolRecognizer::model_names() const {
  std::vector<std::string> names;
  for (const ModelFitter& f : impl_->fitters) names.push_back(f.name());
  return names;
}

RecognitionResult ToolRecognizer::Recognize(const Eigen::Matrix3Xf& p_R,
                                            const std::optional<Eigen::Vector3d>& p_R_camera,
                                            const std::vector<double>& prior,
                                            const std::optional<FitView>& view) const {
  RequireFinite(p_R, "ToolRecognizer::Recognize");
  RequireView(view, "ToolRecognizer::Recognize");
  const std::size_t n = impl_->fitters.size();
  const RecognitionOptions& options = impl_->options;
  if (!prior.empty()) {
    if (prior.size() != n) {
      ThrowInvalid("ToolRecognizer::Recognize: argument prior has ", prior.size(), " entries (expected one per ",
                   "library model, ", n, ")");
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (!(prior[i] >= 0.0) || !std::isfinite(prior[i])) {
        ThrowInvalid("ToolRecognizer::Recognize: argument prior[", i, "] = ", prior[i], " (expected >= 0)");
      }
    }
  }
  RecognitionResult result;
  if (p_R.cols() < kMinFitPoints) {
    result.reason = Cat("observed cloud has ", p_R.cols(), " points (need >= ", kMinFitPoints, ")");
    return result;
  }
  const Eigen::Vector3d seen = PrincipalExtents(p_R);
  result.scores.resize(n);
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d& model = impl_->fitters[i].principal_extents();
    ModelScore& s = result.scores[i];
    s.model = impl_->fitters[i].name();
    s.prior = prior.empty() ? 0.0 : prior[i];
    // Occlusion can shorten the observed length, so a shorter observation costs half as much as
    // a longer one. The width depends on the view (a blade seen edge-on looks thin), so it
    // counts a quarter.
    const double length_ratio = (seen.x() - model.x()) / model.x();
    const double width_ratio = (seen.y() - model.y()) / std::max(model.y(), 1e-3);
    s.extent_distance = (length_ratio > 0 ? 2.0 : 1.0) * std::abs(length_ratio) + 0.25 * std::abs(width_ratio);
    order[i] = i;
  }
  std::size_t candidates = 0;
  if (prior.empty()) {
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return result.scores[a].extent_distance < result.scores[b].extent_distance;
    });
    candidates = std::min<std::size_t>(n, static_cast<std::size_t>(options.max_models));
  } else {
    // The classifier's most probable models, until they hold classifier_mass of the probability.
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return prior[a] > prior[b]; });
    double total = 0.0;
    for (double p : prior) total += p;
    double mass = 0.0;
    while (candidates < std::min<std::size_t>(n, static_cast<std::size_t>(options.max_classifier_candidates))) {
      // A few stray tree votes (1-3 of 100) are noise, not a hypothesis worth a fit.
      if (candidates > 0 && prior[order[candidates]] < options.min_classifier_probability * total) break;
      mass += prior[order[candidates]];
      ++candidates;
      if (mass >= options.classifier_mass * total) break;
    }
  }

  // Verification: each candidate's pose search and a light refinement score how well the model
  // explains the cloud (the coarse search alone confuses a rake with a hoe); the winner alone
  // gets the full refinement, from where its verification left it.
  std::vector<ModelFitResult> searched(n);
  double best_score = std::numeric_limits<double>::infinity();
  const auto search_start = std::chrono::steady_clock::now();
  double search_ms = 0.0;  // of which the pose searches
  for (std::size_t k = 0; k < candidates; ++k) {
    const std::size_t i = order[k];
    const auto t0 = std::chrono::steady_clock::now();
    ModelFitResult search = impl_->fitters[i].Search(p_R, p_R_camera);
    search_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    searched[i] = impl_->fitters[i].Refine(p_R, p_R_camera, std::move(search), options.verify_points,
                                           options.verify_iterations);
    ModelScore& s = result.scores[i];
    s.fitted = true;
    s.score = searched[i].score;
    best_score = std::min(best_score, s.score);
  }
  // Combined evidence: prior (1 without a classifier) times a fit likelihood
  // exp(-(score - best) / confidence_scale), normalised over the verified models.
  double normaliser = 0.0;
  std::size_t best = order[0];
  double best_weight = -1.0;
  for (std::size_t k = 0; k < candidates; ++k) {
    const std::size_t i = order[k];
    const double weight = (prior.empty() ? 1.0 : prior[i]) *
                          std::exp(-(result.scores[i].score - best_score) / options.confidence_scale);
    result.scores[i].posterior = weight;
    normaliser += weight;
    if (weight > best_weight) {
      best_weight = weight;
      best = i;
    }
  }
  double verified_mass = 1.0;
  if (!prior.empty()) {
    double total = 0.0;
    double covered = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      total += prior[i];
      if (result.scores[i].fitted) covered += prior[i];
    }
    verified_mass = total > 0 ? covered / total : 0.0;
  }
  for (ModelScore& s : result.scores) {
    if (s.fitted) s.posterior = normaliser > 0 ? s.posterior / normaliser : 0.0;
  }
  const auto refine_start = std::chrono::steady_clock::now();
  result.fit = impl_->fitters[best].Refine(p_R, p_R_camera, std::move(searched[best]), view);
  const auto refine_end = std::chrono::steady_clock::now();
  result.status = FitStatus::kOk;
  result.model = result.fit.model;
  // Unverified models keep their classifier probability: it is mass the winner cannot claim.
  result.confidence = result.scores[best].posterior * verified_mass;
  internal::Logger()->debug(
      "recognised {} (confidence {:.2f}, score {:.4f} m): {} candidates verified in {:.1f} ms (searches {:.1f} ms), "
      "refined in {:.1f} ms",
      result.model, result.confidence, result.scores[best].score, candidates,
      std::chrono::duration<double, std::milli>(refine_start - search_start).count(), search_ms,
      std::chrono::duration<double, std::milli>(refine_end - refine_start).count());
  return result;
}

}  // namespace toolbench::perception
