#include "control/clearance.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "control/kinematics.h"
#include "robot/robot_description.h"

namespace toolbench::control {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

class ArmClearanceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    robot_ = new robot::RobotDescription(robot::LoadRobotDescription(robot::DefaultRobotSidecar()));
  }
  static void TearDownTestSuite() { delete robot_; }
  static Eigen::Vector3d Palm(const Eigen::VectorXd& q) {
    return MakeRightArmChain(robot_->model, robot_->palm_frame).TipPose(q).translation();
  }
  static ObstacleBox Box(const std::string& name, const Eigen::Vector3d& center, const Eigen::Vector3d& half) {
    ObstacleBox box;
    box.name = name;
    box.X_RB.translation() = center;
    box.half = half;
    return box;
  }
  // The right shoulder's pitch joint moved by `delta` from home.
  static Eigen::VectorXd ShoulderPitch(double delta) {
    Eigen::VectorXd q = robot_->HomeQ();
    q[robot_->model.joints[robot_->model.JointIndex("r_shoulder_pitch")].q_index] += delta;
    return q;
  }
  static robot::RobotDescription* robot_;
};
robot::RobotDescription* ArmClearanceTest::robot_ = nullptr;

TEST_F(ArmClearanceTest, FindsTheHandInsideABoxAndNothingFarAway) {
  const Eigen::VectorXd q = robot_->HomeQ();
  const Eigen::Vector3d palm = Palm(q);
  const ArmClearance around(*robot_, {Box("around", palm, Eigen::Vector3d::Constant(0.02))}, robot_->hand_open, 0.01);
  EXPECT_GT(around.num_spheres(), 20);  // forearm, palm and 15 finger phalanges
  const auto hit = around.Check(q);
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(hit->obstacle, "around");
  EXPECT_LT(hit->distance_m, 0.01);
  EXPECT_LT((hit->p_R - palm).norm(), 0.15);  // a point of the hand or forearm

  const ArmClearance far(*robot_, {Box("far", palm + Eigen::Vector3d(0, 0, 1.0), Eigen::Vector3d::Constant(0.1))},
                         robot_->hand_open, 0.01);
  EXPECT_FALSE(far.Check(q).has_value());
  const ArmClearance none(*robot_, {}, robot_->hand_open, 0.01);
  EXPECT_TRUE(none.empty());
  EXPECT_FALSE(none.Check(q).has_value());
}

TEST_F(ArmClearanceTest, TheMarginCountsFromTheLinksSurface) {
  // A wide slab whose top face is `gap` below the lowest point of the arm at home.
  const Eigen::VectorXd q = robot_->HomeQ();
  const Eigen::Vector3d palm = Palm(q);
  auto slab = [&](double top_z) {
    return Box("slab", Eigen::Vector3d(palm.x(), palm.y(), top_z - 0.05), Eigen::Vector3d(0.5, 0.5, 0.05));
  };
  // Lower the slab until nothing touches it, from inside the hand downward.
  double top = palm.z();
  while (ArmClearance(*robot_, {slab(top)}, robot_->hand_open, 0.0).Check(q)) top -= 0.002;
  EXPECT_LT(top, palm.z() - 0.02);  // the open fingers hang below the palm frame
  EXPECT_FALSE(ArmClearance(*robot_, {slab(top)}, robot_->hand_open, 0.0).Check(q).has_value());
  EXPECT_TRUE(ArmClearance(*robot_, {slab(top)}, robot_->hand_open, 0.01).Check(q).has_value());
  EXPECT_FALSE(ArmClearance(*robot_, {slab(top - 0.012)}, robot_->hand_open, 0.01).Check(q).has_value());
}

TEST_F(ArmClearanceTest, ClosestMeasuresHowDeepTheArmReachesIntoABox) {
  const Eigen::VectorXd q = robot_->HomeQ();
  const Eigen::Vector3d palm = Palm(q);
  auto slab = [&](double top_z) {
    return Box("slab", Eigen::Vector3d(palm.x(), palm.y(), top_z - 0.05), Eigen::Vector3d(0.5, 0.5, 0.05));
  };
  // The slab's top raised by 1 cm steps: the lowest point of the arm goes 1 cm deeper each time.
  const auto clear = ArmClearance(*robot_, {slab(palm.z() - 0.2)}, robot_->hand_open, 0.0).Closest(q);
  ASSERT_TRUE(clear.has_value());
  EXPECT_GT(clear->distance_m, 0.0);
  EXPECT_EQ(clear->obstacle, "slab");
  double last = clear->distance_m;
  for (int i = 1; i <= 5; ++i) {
    const auto hit = ArmClearance(*robot_, {slab(palm.z() - 0.2 + 0.01 * i)}, robot_->hand_open, 0.0).Closest(q);
    ASSERT_TRUE(hit.has_value());
    EXPECT_NEAR(hit->distance_m, last - 0.01, 1e-9);
    last = hit->distance_m;
  }
  // Check finds the same thing once the box is within the margin.
  EXPECT_EQ(ArmClearance(*robot_, {slab(palm.z() - 0.2)}, robot_->hand_open, 0.0).Check(q).has_value(),
            clear->distance_m < 0.0);
  EXPECT_FALSE(ArmClearance(*robot_, {}, robot_->hand_open, 0.01).Closest(q).has_value());
}

TEST_F(ArmClearanceTest, ALineBetweenClearPosturesCanPassThroughABox) {
  const Eigen::VectorXd a = ShoulderPitch(-0.6);
  const Eigen::VectorXd b = ShoulderPitch(0.6);
  const Eigen::VectorXd mid = ShoulderPitch(0.0);
  ASSERT_GT((Palm(a) - Palm(mid)).norm(), 0.15);
  ASSERT_GT((Palm(b) - Palm(mid)).norm(), 0.15);
  const ArmClearance clearance(*robot_, {Box("post", Palm(mid), Eigen::Vector3d::Constant(0.01))}, robot_->hand_open,
                               0.0);
  EXPECT_FALSE(clearance.Check(a).has_value());
  EXPECT_FALSE(clearance.Check(b).has_value());
  const auto hit = clearance.CheckLine(a, b, 0.05);
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(hit->obstacle, "post");
  // Too coarse a step can jump over a small box: the step is what the caller trusts.
  EXPECT_FALSE(clearance.CheckLine(a, b, 10.0).has_value());
  // A line that starts inside the box cannot avoid it: that box is left out.
  EXPECT_FALSE(clearance.CheckLine(mid, b, 0.05).has_value());
}

TEST_F(ArmClearanceTest, RejectsBadInputNamingIt) {
  const Eigen::Vector3d p = Eigen::Vector3d::Zero();
  EXPECT_THAT([&] { ArmClearance(*robot_, {Box("flat", p, Eigen::Vector3d(0.1, 0.0, 0.1))}, robot_->hand_open, 0.01); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("'flat'")));
  EXPECT_THAT([&] { ArmClearance(*robot_, {}, robot_->hand_open, -0.01); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("margin_m")));
  EXPECT_THAT([&] { ArmClearance(*robot_, {}, robot_->hand_open, 0.01, "no_such_link"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no_such_link")));
  EXPECT_THAT([&] { ArmClearance(*robot_, {}, {{"no_such_joint", 0.0}}, 0.01); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no_such_joint")));
  const ArmClearance clearance(*robot_, {Box("b", p, Eigen::Vector3d::Constant(0.1))}, robot_->hand_open, 0.01);
  EXPECT_THAT([&] { clearance.CheckLine(robot_->HomeQ(), robot_->HomeQ(), 0.0); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("max_step_rad")));
}

}  // namespace
}  // namespace toolbench::control
