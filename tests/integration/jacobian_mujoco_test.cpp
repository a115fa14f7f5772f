// The analytic Jacobian of control::KinematicChain equals MuJoCo's mj_jacSite on the composed
// scene, column by column (matched by joint name), at random in-limit postures.
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include "common/paths.h"
#include "common/rng.h"
#include "control/kinematics.h"
#include "robot/robot_description.h"
#include "sim/scene_composer.h"
#include "sim/scene_spec.h"
#include "sim/world.h"
#include "toollib/tool_model.h"

namespace toolbench {
namespace {

constexpr double kJacobianTol = 1e-6;  // [m/rad] and [rad/rad]

TEST(JacobianMujocoTest, AnalyticJacobianEqualsMjJacSite) {
  const sim::SceneSpec spec = sim::LoadSceneSpec(sim::DefaultScenePath());
  const robot::RobotDescription robot = robot::LoadRobotDescription(AssetsDir() / spec.robot);
  const std::vector<toollib::ToolModel> library = toollib::LoadToolLibrary(AssetsDir() / "tools");
  std::vector<std::string> names;
  for (const auto& tool : library) names.push_back(tool.name);
  const sim::ComposedScene scene = sim::ComposeScene(spec, robot, library, sim::PlanScene(spec, names, 1, {}));
  sim::World world(scene.mjcf, "jacobian");
  ASSERT_EQ(world.actuated_joints(), robot.model.JointNames());

  for (const std::string& tip : {robot.palm_frame, robot.camera_frame}) {
    const control::KinematicChain chain(robot.model, robot.root_link, tip);
    const mjModel* m = world.mj_model();
    const int site = mj_name2id(m, mjOBJ_SITE, tip.c_str());
    ASSERT_GE(site, 0) << "no MuJoCo site named '" << tip << "'";
    std::vector<int> dofs;
    for (const std::string& joint : chain.joint_names()) {
      const int id = mj_name2id(m, mjOBJ_JOINT, joint.c_str());
      ASSERT_GE(id, 0) << joint;
      dofs.push_back(m->jnt_dofadr[id]);
    }
    const Eigen::Matrix3d R_RW = scene.X_WR.linear().transpose();
    Rng rng(DeriveSeed(1, "jacobian_mujoco_" + tip));
    std::vector<mjtNum> jacp(3 * m->nv);
    std::vector<mjtNum> jacr(3 * m->nv);
    for (int trial = 0; trial < 50; ++trial) {
      Eigen::VectorXd q(robot.model.num_q());
      for (int i = 0; i < q.size(); ++i) {
        const robot::Joint& joint = robot.model.joints[robot.model.movable_joints[i]];
        q[i] = UniformReal(rng, joint.lower, joint.upper);
      }
      world.TeleportJoints(q);
      mjData* d = world.mj_data();
      mj_forward(m, d);
      mj_jacSite(m, d, jacp.data(), jacr.data(), site);
      const control::ChainJacobian J = chain.Jacobian(q);
      for (int c = 0; c < chain.num_joints(); ++c) {
        Eigen::Vector3d v_W;
        Eigen::Vector3d w_W;
        for (int r = 0; r < 3; ++r) {
          v_W[r] = jacp[r * m->nv + dofs[c]];
          w_W[r] = jacr[r * m->nv + dofs[c]];
        }
        EXPECT_LT((J.col(c).head<3>() - R_RW * v_W).norm(), kJacobianTol)
            << tip << " " << chain.joint_names()[c] << " trial " << trial;
        EXPECT_LT((J.col(c).tail<3>() - R_RW * w_W).norm(), kJacobianTol)
            << tip << " " << chain.joint_names()[c] << " trial " << trial;
      }
    }
  }
}

}  // namespace
}  // namespace toolbench
