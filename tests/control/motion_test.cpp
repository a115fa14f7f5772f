#include "control/motion.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench::control {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

/// A first-order servo: the joint approaches its target with time constant tau.
class FakeRobot : public RobotInterface {
 public:
  explicit FakeRobot(int n) : q_(Eigen::VectorXd::Zero(n)), target_(q_), v_(q_) {}
  std::vector<std::string> JointNames() const override { return {"a", "b"}; }
  Eigen::VectorXd ReadEncoders() const override { return q_; }
  Eigen::VectorXd ReadVelocities() const override { return v_; }
  void SetPositionTargets(const Eigen::VectorXd& q) override { target_ = q; }
  Eigen::VectorXd PositionTargets() const override { return target_; }
  void Wait(double seconds) override {
    for (double t = 0; t < seconds - 1e-12; t += 0.001) {
      v_ = (target_ - q_) / 0.02;
      q_ += v_ * 0.001;
      time_ += 0.001;
    }
  }
  double Time() const override { return time_; }

 private:
  Eigen::VectorXd q_, target_, v_;
  double time_ = 0;
};

TEST(MotionTest, MinJerkProfile) {
  EXPECT_DOUBLE_EQ(MinJerk(0.0), 0.0);
  EXPECT_DOUBLE_EQ(MinJerk(1.0), 1.0);
  EXPECT_DOUBLE_EQ(MinJerk(0.5), 0.5);
  EXPECT_DOUBLE_EQ(MinJerk(-1.0), 0.0);
  // Zero slope at the ends.
  EXPECT_NEAR((MinJerk(1e-4) - MinJerk(0)) / 1e-4, 0.0, 1e-6);
  EXPECT_NEAR((MinJerk(1) - MinJerk(1 - 1e-4)) / 1e-4, 0.0, 1e-6);
}

TEST(MotionTest, MoveJointsReachesGoalAndKeepsOthers) {
  FakeRobot robot(2);
  const MotionResult result = MoveJoints(robot, {{"b", 0.5}});
  EXPECT_TRUE(result.reached);
  EXPECT_NEAR(robot.ReadEncoders()[1], 0.5, 0.02);
  EXPECT_NEAR(robot.ReadEncoders()[0], 0.0, 1e-12);
  EXPECT_GE(result.elapsed, 1.5 - 1e-9);
}

TEST(MotionTest, BadGoalsAreNamed) {
  FakeRobot robot(2);
  EXPECT_THAT([&] { MoveJoints(robot, {{"elbow", 0.5}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("elbow")));
  EXPECT_THAT([&] { MoveJoints(robot, {{"a", NAN}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'a'")));
  MotionOptions options;
  options.duration = 0;
  EXPECT_THAT([&] { MoveJoints(robot, {{"a", 0.1}}, options); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("duration")));
}

}  // namespace
}  // namespace toolbench::control
