// MoveArmAside: the right arm swung up and out of the camera's view of the table, nothing else.
// LookAt: the same target gives the same posture whatever the robot looked at before.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/scene_setup.h"
#include "robot/robot_description.h"
#include "sim/scene_spec.h"
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

// The rack look after the table look turned the torso 59 deg, the same look from the home
// posture 32 deg (the gaze's redundancy was resolved from wherever the neck and torso were), and
// the grasps planned from the two postures differed: 1 of 32 lying tools (rot3) grasped in the
// episode against 19 of 32 in grasp-gt --from-rack-look.
TEST(LookAt, EndsInTheSamePostureWhateverTheRobotLookedAtBefore) {
  const robot::RobotDescription desc = robot::LoadRobotDescription(robot::DefaultRobotSidecar());
  const sim::SceneSpec spec = sim::LoadSceneSpec(sim::DefaultScenePath());
  const std::vector<std::string> names = desc.model.JointNames();
  auto look = [&](FakeArm& robot, const Eigen::Vector3d& target) {
    const LookResult r = LookAt(robot, desc, target);
    EXPECT_TRUE(r.gaze.converged) << target.transpose() << ": " << r.gaze.error_deg << " deg";
    return robot.PositionTargets();
  };
  FakeArm direct(names);
  direct.SetPositionTargets(desc.HomeQ());
  direct.Wait(0.2);
  const Eigen::VectorXd q_direct = look(direct, RackViewTarget(spec));

  FakeArm after_table(names);
  after_table.SetPositionTargets(desc.HomeQ());
  after_table.Wait(0.2);
  const Eigen::VectorXd q_table = look(after_table, {spec.table.center.x(), spec.table.center.y(), spec.table.top_z});
  const Eigen::VectorXd q_after = look(after_table, RackViewTarget(spec));
  EXPECT_GT((q_table - q_direct).cwiseAbs().maxCoeff(), 0.1);  // the table look is elsewhere
  for (size_t i = 0; i < names.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    EXPECT_NEAR(q_after[k], q_direct[k], 1e-6) << names[i];
  }
}

}  // namespace
}  // namespace toolbench::app
