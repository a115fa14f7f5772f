#include "perception/superquadric.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/rng.h"
#include "perception/internal/superquadric_cost.h"

namespace toolbench::perception {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kNoise = 0.0005;        // sensor-like noise on the synthetic points [m]
constexpr double kSizeTol = 0.10;        // relative semi-axis tolerance
constexpr double kCenterTol = 0.002;     // [m]
constexpr double kAxisTolDeg = 5.0;      // [deg]

Eigen::Isometry3d RandomPose(Rng& rng) {
  Eigen::Vector3d axis(StandardNormal(rng), StandardNormal(rng), StandardNormal(rng));
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(UniformReal(rng, 0, M_PI), axis.normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(UniformReal(rng, -0.5, 0.5), UniformReal(rng, -0.5, 0.5), UniformReal(rng, 0, 1));
  return X;
}

Eigen::Vector3d Noise(Rng& rng) {
  return kNoise * Eigen::Vector3d(StandardNormal(rng), StandardNormal(rng), StandardNormal(rng));
}

// Area-uniform samples on a closed cylinder of radius r and half-length h along z.
Eigen::Matrix3Xf Cylinder(double r, double h, int n, const Eigen::Isometry3d& X, Rng& rng) {
  Eigen::Matrix3Xf p(3, n);
  const double side = 2 * M_PI * r * 2 * h, cap = M_PI * r * r;
  for (int i = 0; i < n; ++i) {
    const double u = UniformReal(rng, 0, side + 2 * cap), phi = UniformReal(rng, -M_PI, M_PI);
    Eigen::Vector3d q;
    if (u < side) {
      q = {r * std::cos(phi), r * std::sin(phi), UniformReal(rng, -h, h)};
    } else {
      const double rr = r * std::sqrt(UniformReal(rng, 0, 1));
      q = {rr * std::cos(phi), rr * std::sin(phi), u < side + cap ? h : -h};
    }
    p.col(i) = (X * q + Noise(rng)).cast<float>();
  }
  return p;
}

// Area-uniform samples on a box with half-extents a.
Eigen::Matrix3Xf Box(const Eigen::Vector3d& a, int n, const Eigen::Isometry3d& X, Rng& rng) {
  const Eigen::Vector3d area(a.y() * a.z(), a.x() * a.z(), a.x() * a.y());
  Eigen::Matrix3Xf p(3, n);
  for (int i = 0; i < n; ++i) {
    double u = UniformReal(rng, 0, area.sum());
    int k = 0;
    while (k < 2 && u >= area[k]) u -= area[k++];
    Eigen::Vector3d q(UniformReal(rng, -a.x(), a.x()), UniformReal(rng, -a.y(), a.y()), UniformReal(rng, -a.z(), a.z()));
    q[k] = UniformReal(rng, 0, 1) < 0.5 ? -a[k] : a[k];
    p.col(i) = (X * q + Noise(rng)).cast<float>();
  }
  return p;
}

Eigen::Matrix3Xf Ellipsoid(const Eigen::Vector3d& a, int n, const Eigen::Isometry3d& X, Rng& rng) {
  Eigen::Matrix3Xf p(3, n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = Eigen::Vector3d(StandardNormal(rng), StandardNormal(rng), StandardNormal(rng)).normalized();
    p.col(i) = (X * a.cwiseProduct(d) + Noise(rng)).cast<float>();
  }
  return p;
}

// Checks the fit against a shape with semi-axes `a` (along x, y, z of X): sizes (matched by
// the closest fitted axis direction), centre, and the directions of axes with distinct sizes.
void ExpectRecovered(const SuperquadricFit& fit, const Eigen::Vector3d& a, const Eigen::Isometry3d& X,
                     bool round_xy) {
  ASSERT_EQ(fit.status, SuperquadricStatus::kOk) << fit.reason;
  EXPECT_LT((fit.sq.pose.translation() - X.translation()).norm(), kCenterTol);
  const Eigen::Matrix3d R = fit.sq.pose.linear();
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d truth_axis = X.linear().col(k);
    int best = 0;
    double best_dot = -1;
    for (int j = 0; j < 3; ++j) {
      const double d = std::abs(R.col(j).dot(truth_axis));
      if (d > best_dot) best_dot = d, best = j;
    }
    if (!(round_xy && k < 2)) {
      EXPECT_GT(best_dot, std::cos(kAxisTolDeg * M_PI / 180)) << "axis " << k;
      EXPECT_NEAR(fit.sq.size[best], a[k], kSizeTol * a[k]) << "axis " << k;
    }
  }
  if (round_xy) {
    // Cross-section: the two fitted semi-axes perpendicular to the truth z.
    std::vector<double> cross;
    for (int j = 0; j < 3; ++j) {
      if (std::abs(R.col(j).dot(X.linear().col(2))) < 0.5) cross.push_back(fit.sq.size[j]);
    }
    ASSERT_EQ(cross.size(), 2u);
    for (double s : cross) EXPECT_NEAR(s, a.x(), kSizeTol * a.x());
  }
}

TEST(SuperquadricCostTest, GradientMatchesFiniteDifferences) {
  Rng rng(7);
  const Eigen::Matrix3Xd pts = Box({0.3, 0.5, 1.0}, 60, RandomPose(rng), rng).cast<double>();
  const Eigen::Matrix3d R0 = internal::ExpSo3({0.3, -0.2, 0.5});
  for (int trial = 0; trial < 5; ++trial) {
    internal::SqParams x;
    x << UniformReal(rng, 0.2, 0.6), UniformReal(rng, 0.3, 0.7), UniformReal(rng, 0.7, 1.2), UniformReal(rng, 0.2, 1.8),
        UniformReal(rng, 0.2, 1.8), UniformReal(rng, -0.8, 0.8), UniformReal(rng, -0.8, 0.8),
        UniformReal(rng, -0.8, 0.8), UniformReal(rng, -0.2, 0.2), UniformReal(rng, -0.2, 0.2),
        UniformReal(rng, -0.2, 0.2);
    x.segment<3>(8) += pts.rowwise().mean();
    internal::SqParams g;
    internal::SuperquadricCost(x, pts, R0, &g);
    for (int i = 0; i < 11; ++i) {
      constexpr double kStep = 1e-6;
      internal::SqParams xp = x, xm = x;
      xp[i] += kStep;
      xm[i] -= kStep;
      const double fd = (internal::SuperquadricCost(xp, pts, R0, nullptr) - internal::SuperquadricCost(xm, pts, R0, nullptr)) /
                        (2 * kStep);
      EXPECT_NEAR(g[i], fd, 1e-5 * std::max(1.0, std::abs(fd))) << "trial " << trial << " parameter " << i;
    }
  }
}

TEST(SuperquadricFitTest, RecoversCylinderAtRandomPoses) {
  Rng rng(11);
  for (int trial = 0; trial < 2; ++trial) {
    const Eigen::Isometry3d X = RandomPose(rng);
    const Eigen::Matrix3Xf pts = Cylinder(0.016, 0.040, 2000, X, rng);
    const SuperquadricFit fit = FitSuperquadric(pts, {});
    ExpectRecovered(fit, {0.016, 0.016, 0.040}, X, /*round_xy=*/true);
    EXPECT_LT(fit.sq.e1, 0.5) << "flat ends";
  }
}

TEST(SuperquadricFitTest, RecoversBoxAtRandomPoses) {
  Rng rng(12);
  for (int trial = 0; trial < 2; ++trial) {
    const Eigen::Isometry3d X = RandomPose(rng);
    const Eigen::Vector3d a(0.010, 0.025, 0.050);
    const SuperquadricFit fit = FitSuperquadric(Box(a, 2000, X, rng), {});
    ExpectRecovered(fit, a, X, false);
    EXPECT_LT(std::max(fit.sq.e1, fit.sq.e2), 0.5) << "square edges";
  }
}

TEST(SuperquadricFitTest, RecoversEllipsoidAtRandomPoses) {
  Rng rng(13);
  for (int trial = 0; trial < 2; ++trial) {
    const Eigen::Isometry3d X = RandomPose(rng);
    const Eigen::Vector3d a(0.015, 0.025, 0.045);
    const SuperquadricFit fit = FitSuperquadric(Ellipsoid(a, 2000, X, rng), {});
    ExpectRecovered(fit, a, X, false);
    EXPECT_NEAR(fit.sq.e1, 1.0, 0.2);
    EXPECT_NEAR(fit.sq.e2, 1.0, 0.2);
  }
}

TEST(SuperquadricFitTest, SameSeedSameResult) {
  Rng rng(14);
  const Eigen::Matrix3Xf pts = Cylinder(0.016, 0.040, 1000, RandomPose(rng), rng);
  const SuperquadricFit a = FitSuperquadric(pts, {}), b = FitSuperquadric(pts, {});
  EXPECT_EQ(a.sq.size, b.sq.size);
  EXPECT_EQ(a.sq.pose.matrix(), b.sq.pose.matrix());
}

TEST(SuperquadricFitTest, SurfacePointsLieOnTheSuperquadric) {
  Rng rng(15);
  Superquadric sq;
  sq.size = {0.02, 0.03, 0.05};
  sq.e1 = 0.4;
  sq.e2 = 1.3;
  sq.pose = RandomPose(rng);
  const Eigen::Matrix3Xf s = SuperquadricSurface(sq, 12);
  ASSERT_EQ(s.cols(), 2 * 12 * 12);
  for (Eigen::Index i = 0; i < s.cols(); ++i) {
    EXPECT_NEAR(std::pow(InsideOutside(sq, s.col(i).cast<double>()), sq.e1), 1.0, 1e-3);
  }
}

TEST(SuperquadricMeshTest, ClosedOutwardMeshOnTheSurface) {
  // An ellipsoid (e1 = e2 = 1): every vertex on the surface, every face normal outward, and
  // the area close to the ellipsoid's (Knud Thomsen's formula, error < 1.1 %).
  Rng rng(5);
  Superquadric sq;
  sq.size = Eigen::Vector3d(0.02, 0.03, 0.08);
  sq.pose = RandomPose(rng);
  constexpr int kN = 40;
  const SurfaceMesh mesh = SuperquadricMesh(sq, kN);
  ASSERT_EQ(mesh.vertices.cols(), 2 * kN * kN);
  ASSERT_EQ(mesh.faces.cols(), 2 * kN * (2 * kN - 4));
  EXPECT_TRUE(mesh.vertices.isApprox(SuperquadricSurface(sq, kN)));
  ASSERT_GE(mesh.faces.minCoeff(), 0);
  ASSERT_LT(mesh.faces.maxCoeff(), mesh.vertices.cols());
  const Eigen::Vector3d centre = sq.pose.translation();
  double area = 0.0;
  for (Eigen::Index f = 0; f < mesh.faces.cols(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.col(mesh.faces(0, f)).cast<double>();
    const Eigen::Vector3d b = mesh.vertices.col(mesh.faces(1, f)).cast<double>();
    const Eigen::Vector3d c = mesh.vertices.col(mesh.faces(2, f)).cast<double>();
    const Eigen::Vector3d n = (b - a).cross(c - a);
    ASSERT_GT(n.norm(), 0.0) << "degenerate face " << f;
    EXPECT_GT(n.dot((a + b + c) / 3 - centre), 0.0) << "inward face " << f;
    area += 0.5 * n.norm();
  }
  constexpr double p = 1.6075;
  const double a = sq.size.x(), b = sq.size.y(), c = sq.size.z();
  const double expected =
      4 * M_PI * std::pow((std::pow(a * b, p) + std::pow(a * c, p) + std::pow(b * c, p)) / 3, 1 / p);
  EXPECT_NEAR(area, expected, 0.02 * expected);
  // A box-like superquadric (small exponents) keeps its faces outward too.
  sq.e1 = 0.2;
  sq.e2 = 0.3;
  const SurfaceMesh boxy = SuperquadricMesh(sq, 16);
  for (Eigen::Index f = 0; f < boxy.faces.cols(); ++f) {
    const Eigen::Vector3d a0 = boxy.vertices.col(boxy.faces(0, f)).cast<double>();
    const Eigen::Vector3d b0 = boxy.vertices.col(boxy.faces(1, f)).cast<double>();
    const Eigen::Vector3d c0 = boxy.vertices.col(boxy.faces(2, f)).cast<double>();
    const Eigen::Vector3d n = (b0 - a0).cross(c0 - a0);
    if (n.norm() < 1e-12) continue;  // flat corners of a box-like shape may collapse
    EXPECT_GE(n.dot((a0 + b0 + c0) / 3 - centre), 0.0) << "inward face " << f;
  }
  Superquadric zero;
  EXPECT_THAT([&] { SuperquadricMesh(zero, 8); }, ThrowsMessage<std::invalid_argument>(HasSubstr("sq.size")));
}

TEST(SuperquadricFitTest, BadInput) {
  const SuperquadricFit few = FitSuperquadric(Eigen::Matrix3Xf::Zero(3, 3), {});
  EXPECT_EQ(few.status, SuperquadricStatus::kTooFewPoints);
  EXPECT_THAT(few.reason, HasSubstr("3 points"));
  const SuperquadricFit empty = FitSuperquadric(Eigen::Matrix3Xf(3, 0), {});
  EXPECT_EQ(empty.status, SuperquadricStatus::kTooFewPoints);
  const SuperquadricFit same = FitSuperquadric(Eigen::Matrix3Xf::Ones(3, 50), {});
  EXPECT_EQ(same.status, SuperquadricStatus::kTooFewPoints);
  EXPECT_THAT(same.reason, HasSubstr("span"));
  Eigen::Matrix3Xf nan = Eigen::Matrix3Xf::Ones(3, 50);
  nan(1, 7) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT([&] { FitSuperquadric(nan, {}); }, ThrowsMessage<std::invalid_argument>(HasSubstr("non-finite")));
  SuperquadricOptions bad;
  bad.min_exponent = 0.0;
  EXPECT_THAT([&] { FitSuperquadric(nan, bad); }, ThrowsMessage<std::invalid_argument>(HasSubstr("min_exponent")));
  Superquadric zero;
  EXPECT_THAT([&] { SuperquadricSurface(zero, 8); }, ThrowsMessage<std::invalid_argument>(HasSubstr("sq.size")));
}

}  // namespace
}  // namespace toolbench::perception
