#include "control/kinematics.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/rng.h"
#include "robot/robot_description.h"

namespace toolbench::control {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kJacobianTol = 1e-6;  // analytic vs central differences [m/rad or rad/rad]
constexpr double kPoseTol = 1e-12;     // chain FK vs LinkPoses [m or unitless]
constexpr double kStep = 1e-6;         // finite-difference step [rad]

class KinematicsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    robot_ = new robot::RobotDescription(robot::LoadRobotDescription(robot::DefaultRobotSidecar()));
  }
  static void TearDownTestSuite() { delete robot_; }
  static Eigen::VectorXd RandomQ(Rng& rng) {
    const robot::RobotModel& model = robot_->model;
    Eigen::VectorXd q(model.num_q());
    for (int i = 0; i < q.size(); ++i) {
      const robot::Joint& joint = model.joints[model.movable_joints[i]];
      q[i] = UniformReal(rng, joint.lower, joint.upper);
    }
    return q;
  }
  static robot::RobotDescription* robot_;
};
robot::RobotDescription* KinematicsTest::robot_ = nullptr;

TEST_F(KinematicsTest, RightArmChainHasTheTenJointsInIkinOrder) {
  const KinematicChain chain = MakeRightArmChain(robot_->model);
  EXPECT_EQ(chain.num_joints(), 10);
  EXPECT_EQ(chain.joint_names(), RightArmJointNames());
  EXPECT_EQ(chain.base_link(), robot_->root_link);
  EXPECT_EQ(chain.tip_link(), robot_->palm_frame);
  for (int i = 0; i < chain.num_joints(); ++i) {
    EXPECT_EQ(robot_->model.JointNames()[chain.q_indices()[i]], chain.joint_names()[i]);
    EXPECT_LT(chain.lower()[i], chain.upper()[i]);
  }
}

TEST_F(KinematicsTest, ForwardKinematicsEqualsLinkPose) {
  Rng rng(DeriveSeed(1, "kinematics_fk"));
  for (const std::string& tip : {robot_->palm_frame, robot_->camera_frame}) {
    const KinematicChain chain(robot_->model, robot_->root_link, tip);
    for (int trial = 0; trial < 50; ++trial) {
      const Eigen::VectorXd q = RandomQ(rng);
      const Eigen::Isometry3d expected = robot::LinkPose(robot_->model, q, tip);
      EXPECT_TRUE(chain.TipPose(q).matrix().isApprox(expected.matrix(), kPoseTol)) << tip;
    }
  }
}

TEST_F(KinematicsTest, JacobianEqualsFiniteDifferencesOfForwardKinematics) {
  Rng rng(DeriveSeed(1, "kinematics_jacobian"));
  for (const std::string& tip : {robot_->palm_frame, robot_->camera_frame}) {
    const KinematicChain chain(robot_->model, robot_->root_link, tip);
    for (int trial = 0; trial < 50; ++trial) {
      const Eigen::VectorXd q = RandomQ(rng);
      const ChainJacobian J = chain.Jacobian(q);
      ASSERT_EQ(J.cols(), chain.num_joints());
      for (int i = 0; i < chain.num_joints(); ++i) {
        Eigen::VectorXd q_plus = q;
        Eigen::VectorXd q_minus = q;
        q_plus[chain.q_indices()[i]] += kStep;
        q_minus[chain.q_indices()[i]] -= kStep;
        const Eigen::Isometry3d X_plus = chain.TipPose(q_plus);
        const Eigen::Isometry3d X_minus = chain.TipPose(q_minus);
        const Eigen::Vector3d v = (X_plus.translation() - X_minus.translation()) / (2 * kStep);
        const Eigen::Vector3d w = OrientationError(X_plus.linear(), X_minus.linear()) / (2 * kStep);
        EXPECT_LT((J.col(i).head<3>() - v).norm(), kJacobianTol) << tip << " joint " << chain.joint_names()[i];
        EXPECT_LT((J.col(i).tail<3>() - w).norm(), kJacobianTol) << tip << " joint " << chain.joint_names()[i];
      }
    }
  }
}

TEST_F(KinematicsTest, PalmAtZeroPoseMatchesIkinConvention) {
  // icub.md section 7: at q = 0, x_hand = root -z, z_hand = root -y (palm faces the body).
  const KinematicChain chain = MakeRightArmChain(robot_->model);
  const Eigen::Isometry3d X_RP = chain.TipPose(Eigen::VectorXd::Zero(robot_->model.num_q()));
  EXPECT_TRUE(X_RP.linear().col(0).isApprox(-Eigen::Vector3d::UnitZ(), 1e-6));
  EXPECT_TRUE(X_RP.linear().col(2).isApprox(-Eigen::Vector3d::UnitY(), 1e-6));
}

TEST_F(KinematicsTest, OrientationErrorIsTheRotationBetween) {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d delta(0.1, -0.2, 0.05);
  const Eigen::Matrix3d R_target = Eigen::AngleAxisd(delta.norm(), delta.normalized()) * R;
  EXPECT_TRUE(OrientationError(R_target, R).isApprox(delta, 1e-12));
  EXPECT_LT(OrientationError(R, R).norm(), 1e-12);
}

TEST_F(KinematicsTest, BadInputIsNamed) {
  const KinematicChain chain = MakeRightArmChain(robot_->model);
  EXPECT_THAT([&] { chain.TipPose(Eigen::VectorXd::Zero(3)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("3 entries")));
  Eigen::VectorXd q = Eigen::VectorXd::Zero(robot_->model.num_q());
  q[0] = NAN;
  EXPECT_THAT([&] { chain.Jacobian(q); }, ThrowsMessage<std::invalid_argument>(HasSubstr("non-finite")));
  EXPECT_THAT([&] { KinematicChain(robot_->model, robot_->palm_frame, robot_->root_link); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("not an ancestor")));
  EXPECT_THAT([&] { KinematicChain(robot_->model, robot_->root_link, "r_foot"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("r_foot")));
}

TEST(KinematicsUrdfTest, UrdfWithoutArmJointsGivesClearError) {
  const robot::RobotModel model = robot::ParseUrdf(R"(<?xml version="1.0"?>
<robot name="stick">
  <link name="root_link"/>
  <link name="torso"/>
  <link name="r_hand_dh_frame"/>
  <joint name="torso_pitch" type="revolute">
    <parent link="root_link"/><child link="torso"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="hand_fixed" type="fixed">
    <parent link="torso"/><child link="r_hand_dh_frame"/>
    <origin xyz="0.1 0 0"/>
  </joint>
</robot>)",
                                                   "inline stick");
  EXPECT_THAT([&] { MakeRightArmChain(model); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no movable joint 'torso_roll'")));
  // The generic chain works on it: one joint, tip 0.1 m along the rotated x.
  const KinematicChain chain(model, "root_link", "r_hand_dh_frame");
  ASSERT_EQ(chain.num_joints(), 1);
  const Eigen::VectorXd q = Eigen::VectorXd::Constant(1, M_PI / 2);
  EXPECT_TRUE(chain.TipPose(q).translation().isApprox(Eigen::Vector3d(0, 0.1, 0), 1e-12));
  const ChainJacobian J = chain.Jacobian(q);
  EXPECT_TRUE(J.col(0).isApprox((Eigen::Matrix<double, 6, 1>() << -0.1, 0, 0, 0, 0, 1).finished(), 1e-12));
}

// Evaluate turns coordinate-axis joints (+-x, y, z) by two columns and any other axis by
// angle-axis: each kind, and a prismatic joint, against robot::LinkPose and finite differences.
TEST(KinematicsUrdfTest, EveryKindOfJointAxisMatchesTheModelsLinkPoses) {
  const robot::RobotModel model = robot::ParseUrdf(R"(<?xml version="1.0"?>
<robot name="axes">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/><link name="d"/><link name="e"/><link name="tip"/>
  <joint name="jx" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0.1 0 0" rpy="0.2 0 0"/><axis xyz="1 0 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="jy" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0 0.1 0" rpy="0 0.3 0"/><axis xyz="0 -1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="jz" type="continuous"><parent link="b"/><child link="c"/>
    <origin xyz="0 0 0.1" rpy="0 0 0.4"/><axis xyz="0 0 1"/></joint>
  <joint name="jg" type="revolute"><parent link="c"/><child link="d"/>
    <origin xyz="0.05 0.05 0" rpy="0.1 0.2 0.3"/><axis xyz="0 0.6 0.8"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="jp" type="prismatic"><parent link="d"/><child link="e"/>
    <origin xyz="0 0 0.05"/><axis xyz="0.6 0 -0.8"/><limit lower="-0.1" upper="0.1" effort="1" velocity="1"/></joint>
  <joint name="tip_fixed" type="fixed"><parent link="e"/><child link="tip"/><origin xyz="0.1 0.02 0"/></joint>
</robot>)",
                                                   "inline axes");
  const KinematicChain chain(model, "base", "tip");
  ASSERT_EQ(chain.num_joints(), 5);
  Rng rng(DeriveSeed(1, "kinematics_axes"));
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::VectorXd q(model.num_q());
    for (int i = 0; i < q.size(); ++i) q[i] = UniformReal(rng, -1.0, 1.0) * (i == 4 ? 0.1 : 2.0);
    EXPECT_TRUE(chain.TipPose(q).matrix().isApprox(robot::LinkPose(model, q, "tip").matrix(), kPoseTol));
    const ChainJacobian J = chain.Jacobian(q);
    for (int i = 0; i < chain.num_joints(); ++i) {
      Eigen::VectorXd q_plus = q;
      Eigen::VectorXd q_minus = q;
      q_plus[chain.q_indices()[i]] += kStep;
      q_minus[chain.q_indices()[i]] -= kStep;
      const Eigen::Vector3d v = (chain.TipPose(q_plus).translation() - chain.TipPose(q_minus).translation()) / (2 * kStep);
      const Eigen::Vector3d w =
          OrientationError(chain.TipPose(q_plus).linear(), chain.TipPose(q_minus).linear()) / (2 * kStep);
      EXPECT_LT((J.col(i).head<3>() - v).norm(), kJacobianTol) << chain.joint_names()[i];
      EXPECT_LT((J.col(i).tail<3>() - w).norm(), kJacobianTol) << chain.joint_names()[i];
    }
  }
}

}  // namespace
}  // namespace toolbench::control
