// The right hand really holds a 32 mm handle by contact forces alone.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include "common/paths.h"
#include "common/rng.h"
#include "sim/scene_composer.h"
#include "sim/world.h"

namespace toolbench::sim {
namespace {

class HandTest : public ::testing::Test {
 protected:
  void SetUp() override {
    spec_ = LoadSceneSpec(DefaultScenePath());
    robot_ = robot::LoadRobotDescription(AssetsDir() / spec_.robot);
  }

  /// A posture (model q) with the palm facing up, well above the table, found by seeded search.
  Eigen::VectorXd PalmUpPosture() const {
    Rng rng(DeriveSeed(3, "palm_up"));
    const robot::RobotModel& model = robot_.model;
    Eigen::VectorXd best = robot_.HomeQ();
    double best_score = -1e9;
    for (int trial = 0; trial < 20000; ++trial) {
      Eigen::VectorXd q = robot_.HomeQ();
      for (const char* joint : {"r_shoulder_pitch", "r_shoulder_roll", "r_shoulder_yaw", "r_elbow",
                                "r_wrist_prosup", "r_wrist_pitch", "r_wrist_yaw"}) {
        const robot::Joint& j = model.joints[model.JointIndex(joint)];
        q[j.q_index] = UniformReal(rng, j.lower, j.upper);
      }
      const Eigen::Isometry3d X_RP = robot::LinkPose(model, q, robot_.palm_frame);
      const double up = X_RP.linear().col(2).z();
      const Eigen::Vector3d p = X_RP.translation();
      // Palm up, in front of the chest, clear of the table (top at z = -0.10) and of the body.
      const double score = up - (p.z() < 0.05 ? 1.0 : 0.0) - (p.x() > -0.2 ? 1.0 : 0.0);
      if (score > best_score) {
        best_score = score;
        best = q;
      }
    }
    EXPECT_GT(best_score, 0.97) << "no palm-up posture found";
    return best;
  }

  SceneSpec spec_;
  robot::RobotDescription robot_;
};

TEST_F(HandTest, ClosedHandHoldsA32mmHandleAgainstGravityFromAnyDirection) {
  const Eigen::VectorXd q_arm = PalmUpPosture();
  ScenePlan plan;  // no tools
  ComposedScene scene = ComposeScene(spec_, robot_, {}, plan);
  const Eigen::Isometry3d X_RP = robot::LinkPose(robot_.model, q_arm, robot_.palm_frame);
  // The handle: a 32 mm capsule, 10 cm long, lying along the grasp axis, 2 mm above its place.
  Eigen::Isometry3d X_PH = Eigen::Isometry3d::Identity();
  X_PH.translation() = robot_.grasp.center + Eigen::Vector3d(0, 0, 0.002);
  X_PH.linear() = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), robot_.grasp.axis).toRotationMatrix();
  const Eigen::Isometry3d X_WH = scene.X_WR * X_RP * X_PH;
  const Eigen::Quaterniond q_WH(X_WH.linear());
  char body[512];
  std::snprintf(body, sizeof(body),
                "<body name=\"handle\" pos=\"%.6f %.6f %.6f\" quat=\"%.6f %.6f %.6f %.6f\"><freejoint/>"
                "<geom type=\"capsule\" size=\"0.016 0.034\" mass=\"0.15\" condim=\"4\" friction=\"1 0.01 0.001\" rgba=\"0.8 0.5 0.2 1\"/></body>\n",
                X_WH.translation().x(), X_WH.translation().y(), X_WH.translation().z(), q_WH.w(),
                q_WH.x(), q_WH.y(), q_WH.z());
  std::string mjcf = scene.mjcf;
  mjcf.insert(mjcf.find("  </worldbody>"), body);
  mjcf = mjcf.substr(0, mjcf.find("  <keyframe>")) + "</mujoco>\n";  // the keyframe lacks the handle
  World world(mjcf, "hand test");
  const std::vector<std::string> names = world.actuated_joints();
  auto command = [&](const Eigen::VectorXd& q_model) {
    Eigen::VectorXd q(names.size());
    for (size_t i = 0; i < names.size(); ++i) q[i] = q_model[robot_.model.joints[robot_.model.JointIndex(names[i])].q_index];
    return q;
  };
  world.TeleportJoints(command(robot_.WithJoints(q_arm, robot_.hand_open)));
  ASSERT_TRUE(world.Advance(0.3).ok);  // the handle drops into the open palm
  // Preshape (thumb opposed), then close over 0.5 s.
  const Eigen::VectorXd q_pre = robot_.WithJoints(q_arm, robot_.hand_preshape);
  const Eigen::VectorXd q_closed = robot_.WithJoints(q_arm, robot_.hand_closed);
  for (int i = 1; i <= 30; ++i) {
    world.SetJointTargets(command(q_arm + (q_pre - q_arm) * i / 30.0));
    world.Advance(0.01);
  }
  for (int i = 1; i <= 50; ++i) {
    world.SetJointTargets(command(q_pre + (q_closed - q_pre) * i / 50.0));
    world.Advance(0.01);
  }
  ASSERT_TRUE(world.Advance(0.3).ok);

  auto handle_in_palm = [&]() -> Eigen::Vector3d {
    const GroundTruth truth = world.ground_truth();
    return (truth.Pose(robot_.palm_frame).inverse() * truth.Pose("handle")).translation();
  };
  const Eigen::Vector3d p_held = handle_in_palm();
  EXPECT_LT((p_held - robot_.grasp.center).norm(), 0.015) << p_held.transpose();
  // Now pull the handle out of the hand with gravity turned toward each palm axis in turn
  // (x: toward the fingertips, -x: toward the wrist, +z: out of the palm through the fingers,
  // y: along the handle, where only friction holds), 2 s each.
  mjModel* m = const_cast<mjModel*>(world.mj_model());
  const Eigen::Matrix3d R_WP = world.ground_truth().Pose(robot_.palm_frame).linear();
  for (const Eigen::Vector3d& axis_P : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(-1, 0, 0),
                                        Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0, 1, 0)}) {
    const Eigen::Vector3d g = 9.81 * (R_WP * axis_P);
    for (int k = 0; k < 3; ++k) m->opt.gravity[k] = g[k];
    const Eigen::Vector3d before = handle_in_palm();
    ASSERT_TRUE(world.Advance(2.0).ok);
    const Eigen::Vector3d after = handle_in_palm();
    EXPECT_LT((after - before).norm(), 0.005) << "gravity along palm axis " << axis_P.transpose()
                                               << ": handle slipped " << (after - before).transpose();
    const auto touching = world.ContactingBodies("handle");
    EXPECT_FALSE(touching.empty());
    for (const auto& b : touching) EXPECT_THAT(b, ::testing::StartsWith("r_")) << "handle rests on " << b;
  }
}

}  // namespace
}  // namespace toolbench::sim
