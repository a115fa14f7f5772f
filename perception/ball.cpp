#include "perception/ball.h"

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "common/check.h"
#include "common/rng.h"
#include "perception/object_cloud.h"

namespace toolbench::perception {

void BallDetectionOptions::Validate() const {
  const char* f = "BallDetectionOptions::Validate: ";
  if (!(hue_center_deg >= 0 && hue_center_deg < 360))
    ThrowInvalid(f, "hue_center_deg = ", hue_center_deg, " (expected in [0, 360))");
  if (!(hue_tolerance_deg > 0 && hue_tolerance_deg <= 180))
    ThrowInvalid(f, "hue_tolerance_deg = ", hue_tolerance_deg, " (expected in (0, 180])");
  if (!(min_saturation > 0 && min_saturation < 1))
    ThrowInvalid(f, "min_saturation = ", min_saturation, " (expected in (0, 1))");
  if (!(min_value >= 0 && min_value < 1)) ThrowInvalid(f, "min_value = ", min_value, " (expected in [0, 1))");
  if (min_area_px <= 0) ThrowInvalid(f, "min_area_px = ", min_area_px, " (expected > 0)");
  if (!(expected_radius > 0)) ThrowInvalid(f, "expected_radius = ", expected_radius, " (expected > 0)");
  if (!(radius_tolerance > 0 && radius_tolerance < 1))
    ThrowInvalid(f, "radius_tolerance = ", radius_tolerance, " (expected in (0, 1))");
  if (!(max_rms_error > 0)) ThrowInvalid(f, "max_rms_error = ", max_rms_error, " (expected > 0)");
  if (!(min_depth > 0)) ThrowInvalid(f, "min_depth = ", min_depth, " (expected > 0)");
  if (!(max_depth > min_depth)) ThrowInvalid(f, "max_depth = ", max_depth, " (expected > min_depth)");
}

bool FitSphere(const Eigen::Matrix3Xd& points, Eigen::Vector3d& center, double& radius, double& rms_error) {
  const Eigen::Index n = points.cols();
  if (n < 4) return false;
  // Algebraic fit: |p|^2 + a.p + b = 0 is linear in (a, b); centre -a/2,
  // radius^2 = |a|^2/4 - b. Points are centred first so the system is well
  // conditioned.
  const Eigen::Vector3d mean = points.rowwise().mean();
  Eigen::MatrixXd A(n, 4);
  Eigen::VectorXd rhs(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::Vector3d p = points.col(i) - mean;
    A.row(i) << p.transpose(), 1.0;
    rhs[i] = -p.squaredNorm();
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
  if (svd.singularValues()[3] < 1e-9 * svd.singularValues()[0]) return false;
  const Eigen::Vector4d x = svd.solve(rhs);
  Eigen::Vector3d c = -x.head<3>() / 2;
  const double r2 = c.squaredNorm() - x[3];
  if (!(r2 > 0)) return false;
  double r = std::sqrt(r2);
  // Gauss-Newton on the geometric residuals |p - c| - r (the algebraic fit is
  // biased for a cap).
  for (int iteration = 0; iteration < 20; ++iteration) {
    Eigen::Matrix4d JtJ = Eigen::Matrix4d::Zero();
    Eigen::Vector4d Jtr = Eigen::Vector4d::Zero();
    for (Eigen::Index i = 0; i < n; ++i) {
      const Eigen::Vector3d d = points.col(i) - mean - c;
      const double dist = d.norm();
      if (dist < 1e-12) continue;
      Eigen::Vector4d J;
      J << -d / dist, -1.0;
      const double residual = dist - r;
      JtJ += J * J.transpose();
      Jtr += J * residual;
    }
    const Eigen::Vector4d step = JtJ.ldlt().solve(-Jtr);
    if (!step.allFinite()) return false;
    c += step.head<3>();
    r += step[3];
    if (step.norm() < 1e-9) break;
  }
  if (!(r > 0) || !c.allFinite()) return false;
  double sum = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double e = (points.col(i) - mean - c).norm() - r;
    sum += e * e;
  }
  center = c + mean;
  radius = r;
  rms_error = std::sqrt(sum / static_cast<double>(n));
  return true;
}

namespace {

/// Points of the largest subset that lies on one sphere of about the expected radius (RANSAC on
/// 4-point spheres, fixed seed): the ball when a blob of its colour also holds something else
/// (a red tool touching it). Empty when no such subset of at least 30 points exists.
Eigen::Matrix3Xd SphereConsensus(const Eigen::Matrix3Xd& points, const BallDetectionOptions& options) {
  const Eigen::Index n = points.cols();
  if (n < 30) return {};
  Rng rng(1);
  const double inlier_distance = 0.003;
  std::vector<Eigen::Index> best;
  for (int iteration = 0; iteration < 400; ++iteration) {
    Eigen::Matrix3Xd sample(3, 4);
    for (int k = 0; k < 4; ++k) sample.col(k) = points.col(UniformInt(rng, 0, static_cast<int>(n) - 1));
    Eigen::Vector3d c;
    double r = 0, rms = 0;
    if (!FitSphere(sample, c, r, rms)) continue;
    if (std::fabs(r - options.expected_radius) > options.radius_tolerance * options.expected_radius) continue;
    std::vector<Eigen::Index> inliers;
    for (Eigen::Index i = 0; i < n; ++i) {
      if (std::fabs((points.col(i) - c).norm() - r) < inlier_distance) inliers.push_back(i);
    }
    if (inliers.size() > best.size()) best = std::move(inliers);
  }
  if (best.size() < 30) return {};
  Eigen::Matrix3Xd out(3, static_cast<Eigen::Index>(best.size()));
  for (size_t i = 0; i < best.size(); ++i) out.col(static_cast<Eigen::Index>(i)) = points.col(best[i]);
  return out;
}

}  // namespace

BallDetection DetectBall(const RgbdFrame& frame, const BallDetectionOptions& options) {
  options.Validate();
  if (frame.rgb.empty() || frame.rgb.type() != CV_8UC3) {
    ThrowInvalid("DetectBall: frame.rgb must be a non-empty CV_8UC3 image (got type ", frame.rgb.type(), ")");
  }
  if (frame.depth.type() != CV_32FC1 || frame.depth.size() != frame.rgb.size()) {
    ThrowInvalid("DetectBall: frame.depth must be CV_32FC1 of the rgb image's size ", frame.rgb.cols, "x",
                 frame.rgb.rows);
  }
  // Colour mask. OpenCV's 8-bit HSV has H in [0, 180) (2 degrees a step), S and
  // V in [0, 255].
  cv::Mat hsv;
  cv::cvtColor(frame.rgb, hsv, cv::COLOR_RGB2HSV);
  cv::Mat mask(hsv.size(), CV_8UC1, cv::Scalar(0));
  for (int v = 0; v < hsv.rows; ++v) {
    const cv::Vec3b* row = hsv.ptr<cv::Vec3b>(v);
    unsigned char* m = mask.ptr<unsigned char>(v);
    for (int u = 0; u < hsv.cols; ++u) {
      const double hue = row[u][0] * 2.0;
      double dh = std::fabs(hue - options.hue_center_deg);
      dh = std::min(dh, 360.0 - dh);
      if (dh <= options.hue_tolerance_deg && row[u][1] >= options.min_saturation * 255 &&
          row[u][2] >= options.min_value * 255) {
        m[u] = 255;
      }
    }
  }
  cv::morphologyEx(mask, mask, cv::MORPH_OPEN, cv::getStructuringElement(cv::MORPH_RECT, {3, 3}));
  cv::Mat labels, stats, centroids;
  const int count = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);

  BallDetection best;
  best.reason = "no blob of the ball's colour";
  bool any_blob = false;
  std::string rejections;
  for (int label = 1; label < count; ++label) {
    if (stats.at<int>(label, cv::CC_STAT_AREA) < options.min_area_px) continue;
    any_blob = true;
    const cv::Mat blob = labels == label;
    const Eigen::Matrix3Xf p_C = BackProjectMask(frame, blob, options.min_depth, options.max_depth);
    const cv::Rect roi(stats.at<int>(label, cv::CC_STAT_LEFT), stats.at<int>(label, cv::CC_STAT_TOP),
                       stats.at<int>(label, cv::CC_STAT_WIDTH), stats.at<int>(label, cv::CC_STAT_HEIGHT));
    Eigen::Vector3d c_C;
    double radius = 0, rms = 0;
    Eigen::Matrix3Xd points = p_C.cast<double>();
    bool fitted = FitSphere(points, c_C, radius, rms);
    auto fits_ball = [&] {
      return fitted &&
             std::fabs(radius - options.expected_radius) / options.expected_radius <= options.radius_tolerance &&
             rms <= options.max_rms_error;
    };
    if (!fits_ball()) {
      // Something of the same colour may touch the ball: keep the points of the best sphere.
      const Eigen::Matrix3Xd consensus = SphereConsensus(points, options);
      if (consensus.cols() > 0) {
        Eigen::Vector3d c2;
        double r2 = 0, rms2 = 0;
        if (FitSphere(consensus, c2, r2, rms2)) {
          points = consensus;
          c_C = c2;
          radius = r2;
          rms = rms2;
          fitted = true;
        }
      }
    }
    if (!fitted) {
      rejections += Cat(rejections.empty() ? "" : "; ", "blob at (", roi.x, ", ", roi.y, "): no sphere fits its ",
                        p_C.cols(), " points");
      continue;
    }
    const double relative = std::fabs(radius - options.expected_radius) / options.expected_radius;
    if (relative > options.radius_tolerance || rms > options.max_rms_error) {
      rejections += Cat(rejections.empty() ? "" : "; ", "blob at (", roi.x, ", ", roi.y, "): sphere radius ",
                        radius * 1000, " mm, RMS ", rms * 1000, " mm");
      continue;
    }
    if (best.status != BallStatus::kFound || rms < best.rms_error) {
      best.status = BallStatus::kFound;
      best.reason.clear();
      best.p_RB = frame.X_RC * c_C;
      best.radius = radius;
      best.rms_error = rms;
      best.points = static_cast<int>(points.cols());
      best.roi = roi;
    }
  }
  if (best.status != BallStatus::kFound && any_blob) {
    best.status = BallStatus::kNoSphere;
    best.reason = Cat("no blob of the ball's colour fits a sphere of radius ", options.expected_radius * 1000,
                      " mm: ", rejections);
  }
  return best;
}

}  // namespace toolbench::perception
