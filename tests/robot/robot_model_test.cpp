#include "robot/robot_model.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench::robot {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kTol = 1e-12;

constexpr const char* kTwoLink = R"(
<robot name="two">
  <link name="base"/>
  <link name="upper"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tip"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="2"/>
    <dynamics damping="0.5"/>
  </joint>
  <joint name="tip_fixed" type="fixed">
    <parent link="upper"/><child link="tip"/><origin xyz="0.5 0 0" rpy="0 0 1.5707963267948966"/>
  </joint>
</robot>)";

TEST(RobotModelTest, ParsesTreeParentsFirst) {
  const RobotModel model = ParseUrdf(kTwoLink, "inline");
  ASSERT_EQ(model.links.size(), 3u);
  EXPECT_EQ(model.links[0].name, "base");
  EXPECT_EQ(model.num_q(), 1);
  EXPECT_EQ(model.JointNames(), std::vector<std::string>{"shoulder"});
  const Joint& j = model.joints[model.JointIndex("shoulder")];
  EXPECT_DOUBLE_EQ(j.damping, 0.5);
  EXPECT_DOUBLE_EQ(j.effort, 10);
  EXPECT_DOUBLE_EQ(model.links[model.LinkIndex("upper")].inertial.mass, 1.0);
}

TEST(RobotModelTest, ForwardKinematicsComposesOriginsAndRotations) {
  const RobotModel model = ParseUrdf(kTwoLink, "inline");
  Eigen::VectorXd q(1);
  q << M_PI / 2;  // about +y: the tip at +x swings to -z
  const Eigen::Isometry3d X_tip = LinkPose(model, q, "tip");
  EXPECT_TRUE(X_tip.translation().isApprox(Eigen::Vector3d(0, 0, 0.5), 1e-12))
      << X_tip.translation().transpose();
  // Fixed yaw of 90 deg after the hinge: tip x axis = upper's y axis = world y.
  EXPECT_TRUE((X_tip.linear().col(0)).isApprox(Eigen::Vector3d::UnitY(), kTol));
}

TEST(RobotModelTest, ErrorsNameTheProblem) {
  EXPECT_THAT([] { ParseUrdf("<robot", "broken.urdf"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("broken.urdf")));
  EXPECT_THAT([] { ParseUrdf("", "empty.urdf"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("empty")));
  const RobotModel model = ParseUrdf(kTwoLink, "inline");
  EXPECT_THAT([&] { model.LinkIndex("wrist"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("wrist")));
  EXPECT_THAT([&] { LinkPoses(model, Eigen::VectorXd::Zero(3)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("3 entries")));
  EXPECT_THAT([&] { LinkPoses(model, Eigen::VectorXd::Constant(1, NAN)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("non-finite")));
}

TEST(RobotModelTest, RejectsFloatingJoints) {
  std::string urdf = kTwoLink;
  urdf.replace(urdf.find("type=\"revolute\""), 15, "type=\"floating\"");
  EXPECT_THAT([&] { ParseUrdf(urdf, "floating.urdf"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("unsupported type")));
}

}  // namespace
}  // namespace toolbench::robot
