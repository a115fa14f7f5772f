// The iCub URDF written from shared/facts/icub.md reproduces its published FK test vectors.
#include <cmath>
#include <map>

#include <Eigen/Eigenvalues>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "robot/robot_description.h"

namespace toolbench::robot {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

constexpr double kDeg = M_PI / 180.0;
constexpr double kPosTol = 2e-4;   // the vectors are printed to 0.1 mm
constexpr double kAxisTol = 2e-3;  // and axes to 3 decimals

class IcubModelTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { robot_ = new RobotDescription(LoadRobotDescription(DefaultRobotSidecar())); }
  static void TearDownTestSuite() { delete robot_; }

  Eigen::VectorXd Q(const std::map<std::string, double>& deg) const {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(robot_->model.num_q());
    for (const auto& [name, value] : deg) q[robot_->model.joints[robot_->model.JointIndex(name)].q_index] = value * kDeg;
    return q;
  }
  static RobotDescription* robot_;
};
RobotDescription* IcubModelTest::robot_ = nullptr;

TEST_F(IcubModelTest, HasTheIcubJointsAndFrames) {
  for (const char* joint : {"torso_pitch", "torso_roll", "torso_yaw", "r_shoulder_pitch",
                            "r_shoulder_roll", "r_shoulder_yaw", "r_elbow", "r_wrist_prosup",
                            "r_wrist_pitch", "r_wrist_yaw", "neck_pitch", "neck_roll", "neck_yaw"}) {
    EXPECT_TRUE(robot_->model.joints[robot_->model.JointIndex(joint)].movable()) << joint;
  }
  EXPECT_EQ(robot_->palm_frame, "r_hand_dh_frame");
  EXPECT_EQ(robot_->camera_frame, "helmet_camera");
  // Limits as iKin's defaults (icub.md section 5): shoulder roll 0..160.8 deg.
  const Joint& roll = robot_->model.joints[robot_->model.JointIndex("r_shoulder_roll")];
  EXPECT_NEAR(roll.lower, 0.0, 1e-6);
  EXPECT_NEAR(roll.upper, 160.8 * kDeg, 1e-4);
}

struct ArmVector {
  std::map<std::string, double> q_deg;
  Eigen::Vector3d p, x, z;
};

TEST_F(IcubModelTest, PalmMatchesPublishedVectors) {
  const std::vector<ArmVector> vectors = {
      {{{"torso_pitch", 10}, {"torso_roll", 0}, {"torso_yaw", 30}, {"r_shoulder_pitch", -30},
        {"r_shoulder_roll", 30}, {"r_elbow", 45}},
       {-0.1651, 0.3246, -0.0028}, {-0.661, 0.715, -0.228}, {-0.606, -0.688, -0.400}},
      {{{"r_shoulder_pitch", -60}, {"r_shoulder_roll", 20}, {"r_shoulder_yaw", 10}, {"r_elbow", 80},
        {"r_wrist_prosup", -30}, {"r_wrist_pitch", -10}, {"r_wrist_yaw", 5}},
       {-0.2909, 0.1094, 0.2700}, {-0.727, 0.104, 0.678}, {0.203, -0.911, 0.358}},
  };
  for (const auto& v : vectors) {
    const Eigen::Isometry3d X_RP = LinkPose(robot_->model, Q(v.q_deg), robot_->palm_frame);
    EXPECT_TRUE(X_RP.translation().isApprox(v.p, 1.0) && (X_RP.translation() - v.p).norm() < kPosTol)
        << X_RP.translation().transpose() << " vs " << v.p.transpose();
    EXPECT_LT((X_RP.linear().col(0) - v.x).norm(), kAxisTol) << X_RP.linear().col(0).transpose();
    EXPECT_LT((X_RP.linear().col(2) - v.z).norm(), kAxisTol) << X_RP.linear().col(2).transpose();
  }
}

TEST_F(IcubModelTest, PalmAtZeroAndShoulderCentre) {
  const Eigen::VectorXd q0 = Q({});
  EXPECT_LT((LinkPose(robot_->model, q0, robot_->palm_frame).translation() -
             Eigen::Vector3d(-0.0108, 0.0841, -0.1808)).norm(), kPosTol);
}

TEST_F(IcubModelTest, HelmetCameraMatchesPublishedVector) {
  const Eigen::Isometry3d X_RC = LinkPose(
      robot_->model, Q({{"torso_pitch", 10}, {"torso_yaw", 30}, {"neck_pitch", -20}, {"neck_yaw", -10}}),
      robot_->camera_frame);
  EXPECT_LT((X_RC.translation() - Eigen::Vector3d(-0.2048, 0.0695, 0.3932)).norm(), kPosTol)
      << X_RC.translation().transpose();
  EXPECT_LT((X_RC.linear().col(2) - Eigen::Vector3d(-0.645, 0.613, -0.456)).norm(), kAxisTol)
      << X_RC.linear().col(2).transpose();
  // At zero pose: camera x = root +y (image right), y = root -z (down), z = root -x (forward).
  const Eigen::Isometry3d X0 = LinkPose(robot_->model, Q({}), robot_->camera_frame);
  EXPECT_LT((X0.translation() - Eigen::Vector3d(-0.0831, -0.0175, 0.4625)).norm(), kPosTol);
  EXPECT_LT((X0.linear().col(0) - Eigen::Vector3d(0, 1, 0)).norm(), 1e-6);
  EXPECT_LT((X0.linear().col(2) - Eigen::Vector3d(-1, 0, 0)).norm(), 1e-6);
}

TEST_F(IcubModelTest, EveryLinkHasValidMassProperties) {
  for (const Link& link : robot_->model.links) {
    if (link.parent_joint < 0 || !robot_->model.joints[link.parent_joint].movable()) continue;
    EXPECT_GT(link.inertial.mass, 0.0) << link.name;
    const Eigen::Vector3d d = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(link.inertial.inertia).eigenvalues();
    EXPECT_GT(d.minCoeff(), 0.0) << link.name;
    EXPECT_LE(d.maxCoeff(), d.sum() - d.maxCoeff() + 1e-12) << link.name << " violates the triangle inequality";
  }
}

TEST_F(IcubModelTest, HomeAndHandPosturesAreWithinLimits) {
  for (const auto& q : {robot_->HomeQ(), robot_->WithJoints(robot_->HomeQ(), robot_->hand_closed)}) {
    for (int i = 0; i < robot_->model.num_q(); ++i) {
      const Joint& j = robot_->model.joints[robot_->model.movable_joints[i]];
      EXPECT_GE(q[i], j.lower - 1e-9) << j.name;
      EXPECT_LE(q[i], j.upper + 1e-9) << j.name;
    }
  }
  EXPECT_GE(robot_->hand_groups.size(), 3u);
}

TEST(RobotDescriptionTest, MissingSidecarNamesThePath) {
  EXPECT_THAT([] { LoadRobotDescription("/nonexistent/robot.json"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("/nonexistent/robot.json")));
}

}  // namespace
}  // namespace toolbench::robot
