#include "app/scoring.h"

#include <gtest/gtest.h>

namespace toolbench::app {
namespace {

toollib::ToolModel Hoe() {
  toollib::ToolModel m;
  m.name = "hoe_x";
  m.family = "hoe";
  m.total_length = 0.40;
  m.handle.center = Eigen::Vector3d(0, 0, 0.15);
  m.handle.axis = Eigen::Vector3d::UnitZ();
  m.handle.length = 0.30;
  m.handle.radius = 0.015;
  m.symmetries = {"mirror_y"};
  return m;
}

/// An analysis that places `model` at X_RT with its sidecar handle.
perception::ToolAnalysis Analysis(const toollib::ToolModel& model, const Eigen::Isometry3d& X_RT) {
  perception::ToolAnalysis a;
  a.status = perception::AnalysisStatus::kOk;
  a.model = model.name;
  a.X_RT = X_RT;
  a.handle.center = X_RT * model.handle.center;
  a.handle.axis = X_RT.linear() * model.handle.axis;
  return a;
}

Eigen::Isometry3d Pose(double yaw, const Eigen::Vector3d& p) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
               Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitX()).toRotationMatrix();
  X.translation() = p;
  return X;
}

TEST(ScoreCellTest, ExactPoseIsPerfect) {
  const auto hoe = Hoe();
  const Eigen::Isometry3d X = Pose(0.3, {-0.2, 0.5, 0.1});
  const CellScore s = ScoreCell(Analysis(hoe, X), hoe, X, "hoe");
  EXPECT_EQ(s.score, 1.0);
  EXPECT_EQ(s.verdict, "perfect");
  EXPECT_NEAR(s.handle_error_m, 0.0, 1e-12);
  EXPECT_TRUE(s.recognised);
  EXPECT_TRUE(s.family_recognised);
}

TEST(ScoreCellTest, SmallErrorsStayPerfectLargeOnesDoNot) {
  const auto hoe = Hoe();
  const Eigen::Isometry3d X = Pose(0.3, {-0.2, 0.5, 0.1});
  Eigen::Isometry3d shifted = X;
  shifted.translation() += Eigen::Vector3d(0.01, 0.01, 0.0);
  EXPECT_EQ(ScoreCell(Analysis(hoe, shifted), hoe, X, "hoe").score, 1.0);
  shifted.translation() += Eigen::Vector3d(0.03, 0.0, 0.0);
  const CellScore off = ScoreCell(Analysis(hoe, shifted), hoe, X, "hoe");
  EXPECT_EQ(off.score, 0.0);
  EXPECT_EQ(off.verdict, "centre_off");
  // 30 degrees about the tool's x axis: the handle axis is wrong.
  Eigen::Isometry3d tilted = X * Eigen::AngleAxisd(0.52, Eigen::Vector3d::UnitX());
  EXPECT_EQ(ScoreCell(Analysis(hoe, tilted), hoe, X, "hoe").verdict, "axis_wrong");
}

TEST(ScoreCellTest, EffectorOnTheOtherSideScoresHalf) {
  const auto hoe = Hoe();
  const Eigen::Isometry3d X = Pose(0.3, {-0.2, 0.5, 0.1});
  const Eigen::Isometry3d turned = X * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ());
  const CellScore s = ScoreCell(Analysis(hoe, turned), hoe, X, "hoe");
  EXPECT_EQ(s.score, 0.5);
  EXPECT_EQ(s.verdict, "effector_wrong_side");
  EXPECT_NEAR(s.effector_error_deg, 180.0, 1e-6);
}

TEST(ScoreCellTest, EndToEndFlipScoresHalfUnlessTheShapeIsSymmetric) {
  auto hoe = Hoe();
  const Eigen::Isometry3d X = Pose(0.3, {-0.2, 0.5, 0.1});
  Eigen::Isometry3d X_TT = Eigen::Isometry3d::Identity();
  X_TT.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  X_TT.translation() = Eigen::Vector3d(0, 0, hoe.total_length);
  const Eigen::Isometry3d flipped = X * X_TT;
  const CellScore s = ScoreCell(Analysis(hoe, flipped), hoe, X, "hoe");
  EXPECT_EQ(s.score, 0.5);
  EXPECT_EQ(s.verdict, "flipped");
  // A stick is the same shape either way round and has no working side.
  auto stick = hoe;
  stick.name = "stick_x";
  stick.family = "stick";
  stick.symmetries = {"rot_z_any", "rot_x_180"};
  const CellScore st = ScoreCell(Analysis(stick, flipped), stick, X, "stick");
  EXPECT_EQ(st.score, 1.0) << st.verdict;
  // A shape that is the same turned half about its handle (an untilted spatula): either side.
  Eigen::Isometry3d half = Eigen::Isometry3d::Identity();
  half.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_EQ(ScoreCell(Analysis(hoe, X * half), hoe, X, "hoe").verdict, "effector_wrong_side");
  auto spatula = hoe;
  spatula.symmetries = {"mirror_y", "rot_z_180"};
  const CellScore sp = ScoreCell(Analysis(spatula, X * half), spatula, X, "spatula");
  EXPECT_EQ(sp.score, 1.0) << sp.verdict;
}

TEST(ScoreCellTest, FailedAnalysisScoresZeroAndWrongModelIsNotRecognised) {
  const auto hoe = Hoe();
  const Eigen::Isometry3d X = Pose(0.3, {-0.2, 0.5, 0.1});
  perception::ToolAnalysis failed;
  failed.status = perception::AnalysisStatus::kNoCloud;
  EXPECT_EQ(ScoreCell(failed, hoe, X, "").verdict, "not_found");
  auto a = Analysis(hoe, X);
  a.model = "rake_1";
  const CellScore s = ScoreCell(a, hoe, X, "rake");
  EXPECT_EQ(s.score, 1.0);  // the pose is scored, as in the thesis
  EXPECT_FALSE(s.recognised);
  EXPECT_FALSE(s.family_recognised);
}

}  // namespace
}  // namespace toolbench::app
