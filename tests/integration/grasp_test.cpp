// The right hand grasps tools on the rack from their ground-truth handle pose, lifts them and
// holds them by contact forces alone (issue 4, item 5).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/bench_grasp.h"
#include "app/scene_setup.h"
#include "control/skills.h"

namespace toolbench::app {
namespace {

constexpr double kMinLiftM = 0.05;   // issue 4: tool >= 5 cm above its rest height
constexpr double kMaxSlipM = 0.005;  // issue 4: < 5 mm in the palm during the 2 s hold

// grasp-gt's success: the tool settled on the rack, was grasped, lifted >= kMinLiftM and held
// with < kMaxSlipM of slip, touching nothing but the hand.
void ExpectGraspedLiftedAndHeld(const GraspCaseResult& r) {
  ASSERT_TRUE(r.settled) << "the tool did not come to rest on the rack";
  ASSERT_EQ(r.grasp.status, control::GraspStatus::kGrasped) << r.grasp.reason;
  EXPECT_GE(r.lift_m, kMinLiftM);
  EXPECT_LT(r.slip_m, kMaxSlipM);
  EXPECT_THAT(r.foreign_contacts, ::testing::IsEmpty());
  EXPECT_TRUE(r.success) << r.reason;
}

class GraspTest : public ::testing::TestWithParam<const char*> {};

TEST_P(GraspTest, GraspsLiftsAndHoldsFromGroundTruthHandle) {
  SceneRequest request;
  request.tools = {GetParam()};
  request.cells = {"pos2"};
  const LoadedScene scene = LoadScene(request);
  const GraspCaseResult r = RunGraspCase(scene, GetParam(), "pos2", request.seed);
  ExpectGraspedLiftedAndHeld(r);
}

INSTANTIATE_TEST_SUITE_P(StickAndHoe, GraspTest, ::testing::Values("stick_2", "hoe_2"));

// A tool lying across the rack (cell rot3) catches the board's rail when lifted straight up; the
// lift goes up and back toward the robot (failed with "foreign_contact: rack" before).
TEST(GraspHandle, GraspsAndLiftsAToolLyingAcrossTheRack) {
  SceneRequest request;
  request.tools = {"lstick_2"};
  request.cells = {"rot3"};
  const LoadedScene scene = LoadScene(request);
  const GraspCaseResult r = RunGraspCase(scene, "lstick_2", "rot3", request.seed);
  ExpectGraspedLiftedAndHeld(r);
}

TEST(GraspHandle, RejectsBadInputAndReportsUnreachableHandles) {
  SceneRequest request;
  request.tools = {"stick_2"};
  const LoadedScene scene = LoadScene(request);
  sim::World world(scene.composed.mjcf, "grasp test");
  sim::SimRobot robot(world);
  Eigen::Isometry3d X_RH = Eigen::Isometry3d::Identity();
  X_RH.linear() *= 2.0;  // not a rotation
  EXPECT_THAT([&] { control::GraspHandle(robot, scene.robot, X_RH); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("X_RH")));
  control::GraspOptions bad;
  bad.close_time = 0.1;
  EXPECT_THAT([&] { control::GraspHandle(robot, scene.robot, Eigen::Isometry3d::Identity(), bad); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("close_time")));
  EXPECT_THAT(
      [&] {
        control::GraspToolForAction(robot, scene.robot, Eigen::Isometry3d::Identity(), Eigen::Vector3d::Zero(), -0.1);
      },
      ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("max_slide_m")));
  // 2 m in front of the robot: out of reach, and nothing moves.
  X_RH = Eigen::Isometry3d::Identity();
  X_RH.translation() = Eigen::Vector3d(-2.0, 0.2, 0.0);
  const Eigen::VectorXd before = robot.PositionTargets();
  const control::GraspResult r = control::GraspHandle(robot, scene.robot, X_RH);
  EXPECT_EQ(r.status, control::GraspStatus::kUnreachable);
  EXPECT_FALSE(r.reason.empty());
  EXPECT_EQ(robot.PositionTargets(), before);
}

}  // namespace
}  // namespace toolbench::app
