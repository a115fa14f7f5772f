#include "control/gaze.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench::control {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

class GazeTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    robot_ = new robot::RobotDescription(robot::LoadRobotDescription(robot::DefaultRobotSidecar()));
  }
  static void TearDownTestSuite() { delete robot_; }
  static robot::RobotDescription* robot_;
};
robot::RobotDescription* GazeTest::robot_ = nullptr;

TEST_F(GazeTest, CentresReachableTargets) {
  // On the table in front, and on the rack to the right (needs the torso as well as the neck).
  for (const Eigen::Vector3d& target : {Eigen::Vector3d(-0.45, -0.05, -0.10), Eigen::Vector3d(-0.50, 0.30, -0.10),
                                        Eigen::Vector3d(-0.28, 0.35, 0.02)}) {
    const GazeResult result = LookAt(*robot_, robot_->HomeQ(), target);
    EXPECT_TRUE(result.converged) << target.transpose() << ": " << result.error_deg << " deg";
    const Eigen::Isometry3d X_RC = robot::LinkPose(robot_->model, result.q, robot_->camera_frame);
    const Eigen::Vector3d dir = (target - X_RC.translation()).normalized();
    EXPECT_GT(X_RC.linear().col(2).dot(dir), std::cos(1.0 * M_PI / 180.0));
  }
}

TEST_F(GazeTest, TargetBehindIsReportedNotThrown) {
  const GazeResult result = LookAt(*robot_, robot_->HomeQ(), Eigen::Vector3d(1.0, 0.0, 0.3));
  EXPECT_FALSE(result.converged);
  EXPECT_GT(result.error_deg, 30.0);
}

TEST_F(GazeTest, BadInputIsNamed) {
  EXPECT_THAT([&] { LookAt(*robot_, robot_->HomeQ(), Eigen::Vector3d(NAN, 0, 0)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("not finite")));
  EXPECT_THAT([&] { LookAt(*robot_, Eigen::VectorXd::Zero(2), Eigen::Vector3d(-0.4, 0, 0)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("entries")));
  GazeOptions options;
  options.joint_weights = {{"eyes_roll", 1.0}};
  EXPECT_THAT([&] { LookAt(*robot_, robot_->HomeQ(), Eigen::Vector3d(-0.4, 0, 0), options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("eyes_roll")));
}

}  // namespace
}  // namespace toolbench::control
