// Pull, ball grasp and hand-over skills: bad input gives clear errors, an out-of-reach pull moves
// nothing, and the hand-over fallback holds a tool put into the open hand (issue 4).
#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/bench_pull.h"
#include "app/scene_setup.h"
#include "common/rng.h"
#include "control/skills.h"
#include "sim/world.h"

namespace toolbench::app {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

TEST(PullTest, RejectsBadInput) {
  SceneRequest request;
  request.tools = {"stick_2"};
  const LoadedScene scene = LoadScene(request);
  sim::World world(scene.composed.mjcf, "pull bad input");
  sim::SimRobot robot(world);
  control::ToolEffector effector;
  effector.center_T = Eigen::Vector3d(0, 0, 0.3);
  const Eigen::Isometry3d X_PT = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d nan_target(std::nan(""), 0.0, 0.0);
  EXPECT_THAT([&] { control::PullObject(robot, scene.robot, X_PT, effector, nan_target, 0.035); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("p_RO")));
  const control::ToolEffector no_effector;  // centre NaN: a tool without effector information
  EXPECT_THAT(
      [&] { control::PullObject(robot, scene.robot, X_PT, no_effector, Eigen::Vector3d(-0.5, 0, 0), 0.035); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("no effector information")));
  EXPECT_THAT([&] { control::PullObject(robot, scene.robot, X_PT, effector, Eigen::Vector3d(-0.5, 0, 0), 0.0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("object_radius")));
  control::PullOptions bad;
  bad.drag_waypoints = 1;
  EXPECT_THAT(
      [&] { control::PullObject(robot, scene.robot, X_PT, effector, Eigen::Vector3d(-0.5, 0, 0), 0.035, bad); },
      ThrowsMessage<std::invalid_argument>(HasSubstr("drag_waypoints")));
  EXPECT_THAT([&] { control::GraspBall(robot, scene.robot, nan_target, 0.035); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("p_RB")));
  EXPECT_THAT([&] { control::HandOver(robot, scene.robot, Eigen::Vector3d(-0.2, 0.5, 0), {}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("place")));
  EXPECT_THAT([&] { world.TeleportFreeBody("rack", Eigen::Isometry3d::Identity()); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no free joint")));
  // Out of reach: 2 m away, and nothing moves.
  const Eigen::VectorXd before = robot.PositionTargets();
  const control::PullResult far =
      control::PullObject(robot, scene.robot, X_PT, effector, Eigen::Vector3d(-2.0, 0.0, 0.0), 0.035);
  EXPECT_EQ(far.status, control::PullStatus::kUnreachable);
  EXPECT_EQ(robot.PositionTargets(), before);
}

constexpr double kMinPullM = 0.05;  // issue 4: the ball comes > 5 cm toward the robot

// A tool grasped from its ground-truth handle on the rack reaches behind the ball, which starts
// out of the arm's reach, and drags it toward the robot into reach (pull-gt's case for this tool
// and seed). The tool pivots in the grip as it leaves the rack (rake_4 by less than 10 deg,
// hook_1 by about 45 deg: pull-gt's lift_pivot_deg), so the robot looks at it in the hand and
// plans with the pose it sees (without the look, hook_1 missed the ball).
class PullFromRackTest : public ::testing::TestWithParam<const char*> {};

TEST_P(PullFromRackTest, ToolFromItsGroundTruthHandlePullsTheBallIntoReach) {
  const char* tool = GetParam();
  SceneRequest request;
  request.tools = {tool};
  const LoadedScene scene = LoadScene(request);
  PullCaseOptions options;
  options.put_down_and_grasp_ball = false;
  const PullCaseResult r = RunPullCase(scene, tool, DeriveSeed(request.seed, std::string("pull/") + tool), options);
  EXPECT_FALSE(r.ball_in_reach_before) << "the ball must start out of reach";
  ASSERT_TRUE(r.grasped) << r.reason;
  EXPECT_TRUE(r.inspected) << r.inspect_reason;
  EXPECT_LT(r.used_pose_error_deg, 2.0) << "the in-hand pose seen by the camera vs the truth";
  EXPECT_LT(r.used_effector_error_m, 0.01);
  EXPECT_NE(r.pull.status, control::PullStatus::kUnreachable) << r.pull.reason;
  EXPECT_GT(r.displacement_m, kMinPullM);
  EXPECT_TRUE(r.ball_in_reach) << r.reason;
  EXPECT_EQ(r.pull.status, control::PullStatus::kPulled) << r.pull.reason;
  EXPECT_LT(r.ball_moved_before_drag_m, 0.02) << "the transfer must not touch the ball";
}

INSTANTIATE_TEST_SUITE_P(RakeAndHook, PullFromRackTest, ::testing::Values("rake_4", "hook_1"));

TEST(HandOverTest, ToolPlacedInTheOpenHandIsHeldAndFlaggedAssisted) {
  SceneRequest request;
  request.tools = {"stick_2"};
  const LoadedScene scene = LoadScene(request);
  sim::World world(scene.composed.mjcf, "hand-over");
  world.SettleFreeBodies(scene.spec.physics.settle_time);
  sim::SimRobot robot(world);
  const std::string body = scene.composed.tools.front().body;
  const toollib::ToolModel* model = nullptr;
  for (const auto& t : scene.library) {
    if (t.name == "stick_2") model = &t;
  }
  ASSERT_NE(model, nullptr);
  const Eigen::Isometry3d X_RW = scene.composed.X_WR.inverse();
  const Eigen::Vector3d p_R_tool = X_RW * world.ground_truth().Pose(body).translation();
  int placed = 0;
  // The human: the handle centre onto the hand's grasp cylinder, handle along its axis (the one
  // permitted teleport, counted here as the bench records it).
  const auto place = [&](const Eigen::Isometry3d& X_RP) {
    ++placed;
    Eigen::Isometry3d X_PH = Eigen::Isometry3d::Identity();
    X_PH.linear() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), scene.robot.grasp.axis.normalized())
                        .toRotationMatrix();
    X_PH.translation() = scene.robot.grasp.center;
    Eigen::Isometry3d X_TH = Eigen::Isometry3d::Identity();
    X_TH.translation() = model->handle.center;
    world.TeleportFreeBody(body, scene.composed.X_WR * X_RP * X_PH * X_TH.inverse());
  };
  const control::HandOverResult r = control::HandOver(robot, scene.robot, p_R_tool, place);
  EXPECT_EQ(placed, 1);
  EXPECT_TRUE(r.assisted);
  ASSERT_TRUE(r.holding) << r.reason;
  robot.Wait(1.0);
  // Still in the hand: the handle centre stays near the grasp cylinder's centre.
  const Eigen::Isometry3d X_WP = world.ground_truth().Pose(scene.robot.palm_frame);
  const Eigen::Vector3d p_P_handle =
      X_WP.inverse() * world.ground_truth().Pose(body) * model->handle.center;
  EXPECT_LT((p_P_handle - scene.robot.grasp.center).norm(), 0.05) << p_P_handle.transpose();
}

}  // namespace
}  // namespace toolbench::app
