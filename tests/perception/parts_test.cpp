#include "perception/parts.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <limits>
#include <stdexcept>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench::perception {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

// A part whose points lie on the surface of a box of half-extents `a` around `center` (axes of
// F), with the matching superquadric (as the fit would give) and its score.
Part BoxPart(const Eigen::Vector3d& center, const Eigen::Vector3d& a, const ShapeOptions& options) {
  Part p;
  const int n = 10;  // no grid level exactly on a middle-half boundary
  p.points.resize(3, n * n * n);
  int c = 0;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      for (int k = 0; k < n; ++k) {
        const Eigen::Vector3d u(2.0 * i / (n - 1) - 1, 2.0 * j / (n - 1) - 1, 2.0 * k / (n - 1) - 1);
        if (u.cwiseAbs().maxCoeff() < 1.0) continue;  // inside
        p.points.col(c++) = (center + a.cwiseProduct(u)).cast<float>();
      }
    }
  }
  p.points.conservativeResize(3, c);
  p.sq.size = a;
  p.sq.pose.translation() = center;
  p.cylinder_score = CylinderScore(p.sq, options);
  return p;
}

TEST(CylinderScoreTest, ZeroForTheHandCylinderAndInvariantToAxisOrder) {
  const ShapeOptions options;
  Superquadric sq;
  sq.size = {0.016, 0.016, 0.5 * options.preferred_length};
  EXPECT_DOUBLE_EQ(CylinderScore(sq, options), 0.0);
  sq.size = {0.014, 0.060, 0.013};
  const double score = CylinderScore(sq, options);
  sq.size = {0.060, 0.013, 0.014};
  EXPECT_DOUBLE_EQ(CylinderScore(sq, options), score);
  sq.size = {0.013, 0.014, 0.060};
  EXPECT_DOUBLE_EQ(CylinderScore(sq, options), score);
  EXPECT_GT(score, 0.0);  // shorter than preferred_length
  // A thin blade (2.5 mm x 40 mm x 40 mm) is far from a handle; a long 13 mm rod is close.
  sq.size = {0.0025, 0.040, 0.040};
  const double blade = CylinderScore(sq, options);
  sq.size = {0.013, 0.013, 0.12};
  EXPECT_GT(blade, 1.0);
  EXPECT_LT(CylinderScore(sq, options), 0.1);
}

TEST(ChooseHandleTest, PicksTheRodAndPointsTowardTheRest) {
  const ShapeOptions options;
  std::vector<Part> parts;
  // A blade at the top (z = 0.26) reaching toward +x, and a handle rod below it along z.
  parts.push_back(BoxPart({0.02, 0, 0.26}, {0.04, 0.04, 0.0025}, options));
  parts.push_back(BoxPart({0, 0, 0.13}, {0.013, 0.013, 0.125}, options));
  const Handle h = ChooseHandle(parts, options);
  ASSERT_EQ(h.part, 1);
  EXPECT_GT(h.axis.z(), 0.99);  // toward the blade
  EXPECT_NEAR(h.center.z(), 0.13, 1e-3);
  EXPECT_NEAR(h.length, 0.25, 1e-3);
  EXPECT_GT(h.X_FH.linear().col(0).x(), 0.99);  // x_H toward the blade's side
  EXPECT_TRUE(h.X_FH.linear().isUnitary(1e-9));
  EXPECT_NEAR(h.X_FH.linear().determinant(), 1.0, 1e-9);

  const ToolFeatures f = ComputeFeatures(parts, h, Eigen::Isometry3d::Identity());
  EXPECT_NEAR(f.total_length, 0.2575, 1e-3);
  EXPECT_NEAR(f.effector_center.x(), 0.02, 1e-3);
  EXPECT_NEAR(f.effector_protrusion, 0.06, 1e-3);
  EXPECT_NEAR(f.effector_size.y(), 0.08, 1e-3);

  // Flipped tool (blade at the bottom): the axis follows the geometry, not the frame.
  std::vector<Part> flipped;
  flipped.push_back(BoxPart({0.02, 0, -0.26}, {0.04, 0.04, 0.0025}, options));
  flipped.push_back(BoxPart({0, 0, -0.13}, {0.013, 0.013, 0.125}, options));
  EXPECT_LT(ChooseHandle(flipped, options).axis.z(), -0.99);
}

TEST(ChooseHandleTest, LonePartUsesTheHintAndKeepsTheEffectorEndOut) {
  const ShapeOptions options;
  std::vector<Part> parts{BoxPart({0, 0, 0.175}, {0.011, 0.011, 0.175}, options)};
  Handle h = ChooseHandle(parts, options, Eigen::Vector3d::UnitZ());
  ASSERT_EQ(h.part, 0);
  EXPECT_GT(h.axis.z(), 0.99);
  EXPECT_NEAR(h.length, 0.35 - options.lone_part_effector_length, 1e-3);
  EXPECT_NEAR(h.center.z(), 0.135, 1e-3);
  h = ChooseHandle(parts, options, -Eigen::Vector3d::UnitZ());
  EXPECT_LT(h.axis.z(), -0.99);
  EXPECT_NEAR(h.center.z(), 0.215, 1e-3);
}

TEST(ChooseHandleTest, NoHandleWhenNothingIsCylindrical) {
  ShapeOptions options;
  std::vector<Part> parts{BoxPart({0, 0, 0}, {0.002, 0.1, 0.1}, options)};
  EXPECT_EQ(ChooseHandle(parts, options).part, -1);
  EXPECT_EQ(ChooseHandle({}, options).part, -1);
}

TEST(SegmentPartsTest, BadInput) {
  const ShapeOptions options;
  SurfaceSamples three;
  three.points = Eigen::Matrix3Xf::Identity(3, 3);
  three.normals = Eigen::Matrix3Xf::Zero(3, 3);
  const PartsResult few = SegmentParts(three, options);
  EXPECT_EQ(few.status, ShapeStatus::kTooFewPoints);
  EXPECT_THAT(few.reason, HasSubstr("3 points"));
  const PartsResult empty = SegmentParts(SurfaceSamples{}, options);
  EXPECT_EQ(empty.status, ShapeStatus::kTooFewPoints);
  EXPECT_THAT(empty.reason, HasSubstr("0 points"));

  SurfaceSamples nan;
  nan.points = Eigen::Matrix3Xf::Zero(3, 100);
  nan.normals = Eigen::Matrix3Xf::Zero(3, 100);
  nan.points(2, 5) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT([&] { SegmentParts(nan, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("samples.points contains a non-finite")));
  SurfaceSamples mismatch;
  mismatch.points = Eigen::Matrix3Xf::Zero(3, 100);
  mismatch.normals = Eigen::Matrix3Xf::Zero(3, 99);
  EXPECT_THAT([&] { SegmentParts(mismatch, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("samples.normals has 99 columns")));
  EXPECT_THAT([&] { AnalyzeObservedShape(nan.points, Eigen::Vector3d::Zero(), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("p_R contains a non-finite")));
  EXPECT_EQ(AnalyzeObservedShape(three.points, Eigen::Vector3d::Zero(), options).status, ShapeStatus::kTooFewPoints);
  ShapeOptions bad;
  bad.sdf_clusters = 1;
  EXPECT_THAT([&] { SegmentParts(three, bad); }, ThrowsMessage<std::invalid_argument>(HasSubstr("sdf_clusters = 1")));
  bad = {};
  bad.preferred_length = 0.01;
  EXPECT_THAT([&] { bad.Validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("preferred_length")));
}

TEST(TransformShapeTest, MovesPartsHandleAndToolFrame) {
  const ShapeOptions options;
  ModelShape shape;
  shape.parts.push_back(BoxPart({0.02, 0, 0.26}, {0.04, 0.04, 0.0025}, options));
  shape.parts.push_back(BoxPart({0, 0, 0.13}, {0.013, 0.013, 0.125}, options));
  shape.handle = ChooseHandle(shape.parts, options);
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();
  X_RT.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  X_RT.translation() = Eigen::Vector3d(0.3, -0.2, 0.1);
  const ModelShape moved = TransformShape(shape, X_RT);
  EXPECT_TRUE(moved.handle.center.isApprox(X_RT * shape.handle.center, 1e-12));
  EXPECT_TRUE(moved.handle.axis.isApprox(X_RT.linear() * shape.handle.axis, 1e-12));
  EXPECT_TRUE(moved.X_FT.isApprox(X_RT, 1e-12));
  EXPECT_TRUE(moved.parts[1].sq.pose.isApprox(X_RT * shape.parts[1].sq.pose, 1e-12));
  EXPECT_TRUE(moved.parts[0].points.col(7).isApprox((X_RT.cast<float>() * shape.parts[0].points.col(7)), 1e-5f));
  // Re-choosing the handle in R gives the moved handle.
  const Handle again = ChooseHandle(moved.parts, options);
  EXPECT_LT((again.center - moved.handle.center).norm(), 1e-3);
  EXPECT_GT(again.axis.dot(moved.handle.axis), 0.9999);
}

TEST(WritePartsPlyTest, WritesOneColouredVertexPerPointAndSurfacePoint) {
  const ShapeOptions options;
  std::vector<Part> parts;
  parts.push_back(BoxPart({0.02, 0, 0.26}, {0.04, 0.04, 0.0025}, options));
  parts.push_back(BoxPart({0, 0, 0.13}, {0.013, 0.013, 0.125}, options));
  const std::filesystem::path path = std::filesystem::path(::testing::TempDir()) / "parts_test.ply";
  WritePartsPly(path, parts, 1, 50);  // n = 5: 2 * 5 * 5 surface points per part
  std::ifstream in(path);
  std::string line;
  long vertices = -1, body = 0;
  bool header = true;
  while (std::getline(in, line)) {
    if (header) {
      if (line.rfind("element vertex ", 0) == 0) vertices = std::stol(line.substr(15));
      if (line == "end_header") header = false;
      continue;
    }
    ++body;
    if (body == parts[0].points.cols() + 50 + 1) {
      EXPECT_NE(line.find(" 40 90 230"), std::string::npos) << line;
    }
  }
  EXPECT_EQ(vertices, parts[0].points.cols() + parts[1].points.cols() + 100);
  EXPECT_EQ(body, vertices);
  std::filesystem::remove(path);
  EXPECT_THAT([&] { WritePartsPly("/nonexistent_dir/x.ply", parts, 0); },
              ThrowsMessage<std::runtime_error>(HasSubstr("/nonexistent_dir/x.ply")));
}

}  // namespace
}  // namespace toolbench::perception
