// MoveArmAside: the right arm swung up and out of the camera's view of the table, nothing else.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/scene_setup.h"
#include "tests/common/first_order_robot.h"

namespace toolbench::app {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

using FakeArm = test::FirstOrderRobot;

TEST(MoveArmAside, AbductsTheShoulderAndKeepsEveryOtherJoint) {
  FakeArm robot({"torso_yaw", "r_shoulder_pitch", "r_shoulder_roll", "r_elbow"});
  const Eigen::Vector4d start(0.3, -1.5, 0.5, 1.2);  // a forearm across the view (random episode 14)
  robot.SetPositionTargets(start);
  robot.Wait(0.5);
  const control::MotionResult aside = MoveArmAside(robot);
  EXPECT_TRUE(aside.reached) << aside.worst_joint;
  EXPECT_GT(aside.elapsed, 0.0);
  const Eigen::VectorXd after = robot.PositionTargets();
  EXPECT_DOUBLE_EQ(after[2], kArmAsideShoulderRollRad);
  EXPECT_NEAR(robot.ReadEncoders()[2], kArmAsideShoulderRollRad, 0.02);
  for (int i : {0, 1, 3}) EXPECT_EQ(after[i], start[i]) << robot.JointNames()[i] << " moved";
  // At the transfer speed: 0.9 rad at 1.5 rad/s peak is 1.125 s of trajectory.
  EXPECT_LT(aside.elapsed, 1.125 + 0.3);

  // Already out that far: nothing moves, no time passes.
  const double t = robot.Time();
  const control::MotionResult again = MoveArmAside(robot);
  EXPECT_TRUE(again.reached);
  EXPECT_EQ(again.elapsed, 0.0);
  EXPECT_EQ(robot.Time(), t);
}

TEST(MoveArmAside, NamesTheMissingJoint) {
  FakeArm robot({"torso_yaw", "l_shoulder_roll"});
  EXPECT_THAT([&] { MoveArmAside(robot); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("r_shoulder_roll")));
}

}  // namespace
}  // namespace toolbench::app
