#include "control/motion.h"

#include <algorithm>
#include <functional>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/common/first_order_robot.h"

namespace toolbench::control {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

/// Joints "a" and "b" as first-order servos.
class FakeRobot : public test::FirstOrderRobot {
 public:
  explicit FakeRobot(int /*joints: always a and b*/) : FirstOrderRobot({"a", "b"}) {}
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

TEST(MotionTest, CruiseProfileMovesAtAnEvenPaceBetweenShortRamps) {
  // blend 0: minimum jerk.
  for (const double tau : {0.1, 0.37, 0.8}) EXPECT_DOUBLE_EQ(CruiseProfile(tau, 0.0), MinJerk(tau));
  const double blend = 0.25;
  EXPECT_DOUBLE_EQ(CruiseProfile(0.0, blend), 0.0);
  EXPECT_DOUBLE_EQ(CruiseProfile(1.0, blend), 1.0);
  EXPECT_DOUBLE_EQ(CruiseProfile(-0.5, blend), 0.0);
  EXPECT_DOUBLE_EQ(CruiseProfile(1.5, blend), 1.0);
  EXPECT_NEAR(CruiseProfile(0.5, blend), 0.5, 1e-12);  // symmetric
  // Constant speed 1 / (1 - blend) between the ramps, continuous where they meet, zero at the ends.
  const double v = 1.0 / (1.0 - blend);
  auto speed = [&](double tau) { return (CruiseProfile(tau + 1e-6, blend) - CruiseProfile(tau - 1e-6, blend)) / 2e-6; };
  for (const double tau : {blend, 0.3, 0.5, 0.7, 1.0 - blend}) EXPECT_NEAR(speed(tau), v, 1e-5) << tau;
  EXPECT_NEAR((CruiseProfile(1e-4, blend) - CruiseProfile(0, blend)) / 1e-4, 0.0, 1e-3);
  EXPECT_NEAR((CruiseProfile(1, blend) - CruiseProfile(1 - 1e-4, blend)) / 1e-4, 0.0, 1e-3);
  // Monotonic, and never faster than the cruise.
  double previous = 0.0;
  for (int i = 1; i <= 1000; ++i) {
    const double s = CruiseProfile(i / 1000.0, blend);
    EXPECT_GE(s, previous);
    EXPECT_LE(s - previous, v / 1000.0 + 1e-12);
    previous = s;
  }
  EXPECT_THAT([] { CruiseProfile(0.5, 0.6); }, ThrowsMessage<std::invalid_argument>(HasSubstr("blend")));
  MotionOptions bad;
  bad.cruise_blend = 0.7;
  FakeRobot robot(2);
  EXPECT_THAT([&] { MoveJoints(robot, {{"a", 0.1}}, bad); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("cruise_blend")));
}

TEST(MotionTest, MoveJointsReachesGoalAndKeepsOthers) {
  FakeRobot robot(2);
  const MotionResult result = MoveJoints(robot, {{"b", 0.5}});
  EXPECT_TRUE(result.reached);
  EXPECT_NEAR(robot.ReadEncoders()[1], 0.5, 0.02);
  EXPECT_NEAR(robot.ReadEncoders()[0], 0.0, 1e-12);
  EXPECT_GE(result.elapsed, 1.5 - 1e-9);
}

TEST(MotionTest, AJointThatCannotArriveDoesNotHoldUpTheOthers) {
  FakeRobot robot(2);
  robot.blocked[0] = true;  // "a"
  robot.SetPositionTargets(Eigen::Vector2d(0.5, 0.0));  // "a" squeezes: it never gets there
  MotionOptions options;
  options.timeout = 2.0;
  const MotionResult result = MoveJoints(robot, {{"b", 0.5}}, options);
  EXPECT_TRUE(result.reached);
  EXPECT_EQ(result.worst_joint, "b");
  EXPECT_LT(result.elapsed, options.duration + 0.2);
  // Moving "a" itself does wait, and says which joint is off.
  const MotionResult stuck = MoveJoints(robot, {{"a", 0.6}}, options);
  EXPECT_FALSE(stuck.reached);
  EXPECT_EQ(stuck.worst_joint, "a");
  EXPECT_NEAR(stuck.elapsed, options.duration + options.timeout, 0.02);
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

TEST(MotionTest, ASpeedLimitedMotionLastsAsLongAsItsLargestJointChangeNeeds) {
  MotionOptions options;
  options.duration = 2.0;
  options.max_speed = 1.5;
  options.min_duration = 0.3;
  // 0.4 rad at a 1.5 rad/s peak: 1.875 * 0.4 / 1.5 = 0.5 s; 2 rad would need 2.5 s (capped at
  // duration); 2 mrad would need 2.5 ms (raised to min_duration). Without max_speed: duration.
  EXPECT_NEAR(options.TrajectoryTime(0.4, options.duration), 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(options.TrajectoryTime(2.0, options.duration), 2.0);
  EXPECT_DOUBLE_EQ(options.TrajectoryTime(2e-3, options.duration), 0.3);
  MotionOptions fixed = options;
  fixed.max_speed = 0;
  EXPECT_DOUBLE_EQ(fixed.TrajectoryTime(0.4, fixed.duration), 2.0);

  // Executed: the short move arrives after ~0.5 s, the peak commanded speed stays at the limit.
  class Recorder : public FakeRobot {
   public:
    using FakeRobot::FakeRobot;
    double peak_speed = 0;  // of the commanded targets [rad/s]
    void SetPositionTargets(const Eigen::VectorXd& q) override {
      peak_speed = std::max(peak_speed, (q - PositionTargets()).cwiseAbs().maxCoeff() / 0.01);
      FakeRobot::SetPositionTargets(q);
    }
  } robot(2);
  const MotionResult result = MoveJoints(robot, {{"a", 0.4}, {"b", -0.1}}, options);
  EXPECT_TRUE(result.reached);
  EXPECT_GE(result.elapsed, 0.5 - 1e-9);
  EXPECT_LT(result.elapsed, 0.5 + 0.2);
  EXPECT_LE(robot.peak_speed, 1.5 + 1e-3);
  EXPECT_GT(robot.peak_speed, 1.4);
  // MoveThrough: the whole path's length counts (0.4 + 0.4 rad: 1.0 s, under 2 x duration).
  const MotionResult path = MoveThrough(robot, {{{"a", 0.0}}, {{"b", 0.3}}}, options);
  EXPECT_TRUE(path.reached);
  EXPECT_GE(path.elapsed, 1.0 - 1e-9);
  EXPECT_LT(path.elapsed, 1.0 + 0.2);

  MotionOptions bad = options;
  bad.max_speed = -1;
  EXPECT_THAT([&] { MoveJoints(robot, {{"a", 0.1}}, bad); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("max_speed")));
  bad = options;
  bad.min_duration = 0;
  EXPECT_THAT([&] { MoveJoints(robot, {{"a", 0.1}}, bad); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("min_duration")));
}

TEST(MotionTest, AMotionToWhereTheTargetsAreOnlyWaitsForArrival) {
  MotionOptions options;  // fixed 1.5 s
  EXPECT_DOUBLE_EQ(options.TrajectoryTime(0.0, options.duration), 0.0);
  EXPECT_DOUBLE_EQ(options.TrajectoryTime(kNegligibleSpanRad, options.duration), 0.0);
  EXPECT_DOUBLE_EQ(options.TrajectoryTime(2 * kNegligibleSpanRad, options.duration), 1.5);
  options.max_speed = 1.5;
  EXPECT_DOUBLE_EQ(options.TrajectoryTime(0.0, options.duration), 0.0);
  FakeRobot robot(2);
  ASSERT_TRUE(MoveJoints(robot, {{"a", 0.3}}).reached);
  // Already there and still: no trajectory time, for one goal and for a path of them.
  const MotionResult same = MoveJoints(robot, {{"a", 0.3}, {"b", 0.0}});
  EXPECT_TRUE(same.reached);
  EXPECT_LT(same.elapsed, 0.05);
  const MotionResult path = MoveThrough(robot, {{{"a", 0.3}}, {{"b", 0.0}}, {{"a", 0.3}}});
  EXPECT_TRUE(path.reached);
  EXPECT_LT(path.elapsed, 0.05);
  // Targets there but the encoders not yet: it waits for them as any motion does.
  robot.SetPositionTargets(Eigen::Vector2d(0.6, 0.0));
  const MotionResult catching_up = MoveJoints(robot, {{"a", 0.6}});
  EXPECT_TRUE(catching_up.reached);
  EXPECT_GT(catching_up.elapsed, 0.05);
  EXPECT_NEAR(robot.ReadEncoders()[0], 0.6, options.position_tol);
}

TEST(MotionTest, MoveThroughPassesEveryGoalWithoutStopping) {
  FakeRobot robot(2);
  MotionOptions options;
  options.duration = 0.5;  // per goal
  // An L-shaped path: a first, then b. The targets must pass the corner (0.4, 0).
  double closest_to_corner = 1e9;
  double elapsed_at_corner = -1;
  double speed_at_corner = -1;  // of the targets [rad/s]
  Eigen::VectorXd previous = Eigen::Vector2d::Zero();
  class Recorder : public FakeRobot {
   public:
    using FakeRobot::FakeRobot;
    std::function<void(const Eigen::VectorXd&, double)> on_target;
    void SetPositionTargets(const Eigen::VectorXd& q) override {
      FakeRobot::SetPositionTargets(q);
      if (on_target) on_target(q, Time());
    }
  } recorder(2);
  recorder.on_target = [&](const Eigen::VectorXd& q, double t) {
    const double d = (q - Eigen::Vector2d(0.4, 0.0)).norm();
    if (d < closest_to_corner) {
      closest_to_corner = d;
      elapsed_at_corner = t;
      speed_at_corner = (q - previous).norm() / options.command_period;
    }
    previous = q;
  };
  const MotionResult result = MoveThrough(recorder, {{{"a", 0.4}}, {{"b", 0.4}}}, options);
  EXPECT_TRUE(result.reached);
  EXPECT_NEAR(recorder.ReadEncoders()[0], 0.4, 0.02);
  EXPECT_NEAR(recorder.ReadEncoders()[1], 0.4, 0.02);
  EXPECT_LT(closest_to_corner, 0.02);
  EXPECT_NEAR(elapsed_at_corner, 0.5, 0.05);  // half the path at half the time (equal segments)
  // Passing the corner at the minimum-jerk peak speed 1.875 * 0.8 rad / 1 s, not stopping there.
  EXPECT_NEAR(speed_at_corner, 1.5, 0.1);
  // One motion of 2 x 0.5 s plus the arrival; stopping at the corner would add its own wait.
  EXPECT_GE(result.elapsed, 1.0 - 1e-9);
  EXPECT_LT(result.elapsed, 1.0 + 0.2);

  // Cruising (MotionOptions::cruise_blend): the corner is passed at the cruise speed
  // 0.8 rad / 1 s / (1 - 0.25), and the motion takes as long.
  options.cruise_blend = 0.25;
  closest_to_corner = 1e9;
  previous = recorder.ReadEncoders();
  const double t_cruise = recorder.Time();
  const MotionResult back = MoveThrough(recorder, {{{"b", 0.0}}, {{"a", 0.0}}}, options);  // back past the corner
  EXPECT_TRUE(back.reached);
  EXPECT_NEAR(elapsed_at_corner - t_cruise, 0.5, 0.05);
  EXPECT_NEAR(speed_at_corner, 0.8 / 0.75, 0.05);
  EXPECT_LT(back.elapsed, 1.0 + 0.2);

  // Nothing to do: no motion, no time.
  const MotionResult none = MoveThrough(robot, {}, options);
  EXPECT_TRUE(none.reached);
  EXPECT_EQ(none.elapsed, 0.0);
  EXPECT_THAT([&] { MoveThrough(robot, {{{"a", 0.1}}, {{"wrist", 0.2}}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("MoveThrough: unknown joint 'wrist'")));
  EXPECT_THAT([&] { MoveThrough(robot, {{{"b", INFINITY}}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'b'")));
}

}  // namespace
}  // namespace toolbench::control
