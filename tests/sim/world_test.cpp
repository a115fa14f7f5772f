#include "sim/world.h"

#include <algorithm>
#include <utility>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include "common/paths.h"
#include "common/rng.h"
#include "sim/scene_composer.h"

namespace toolbench::sim {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

class WorldTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    spec_ = new SceneSpec(LoadSceneSpec(DefaultScenePath()));
    robot_ = new robot::RobotDescription(robot::LoadRobotDescription(AssetsDir() / spec_->robot));
    library_ = new std::vector<toollib::ToolModel>(toollib::LoadToolLibrary(AssetsDir() / "tools"));
    for (const auto& t : *library_) names_.push_back(t.name);
  }
  static void TearDownTestSuite() {
    delete spec_;
    delete robot_;
    delete library_;
  }
  ComposedScene Compose(std::uint64_t seed, const std::vector<ToolPlacement>& tools = {},
                        const SceneSpec* spec = nullptr) const {
    const SceneSpec& s = spec ? *spec : *spec_;
    return ComposeScene(s, *robot_, *library_, PlanScene(s, names_, seed, tools));
  }
  // The default scene with plain MuJoCo physics (no sleeping): what the contact model does itself.
  static SceneSpec Awake() {
    SceneSpec spec = *spec_;
    spec.physics.sleep_window = 0.0;
    return spec;
  }
  static SceneSpec* spec_;
  static robot::RobotDescription* robot_;
  static std::vector<toollib::ToolModel>* library_;
  static std::vector<std::string> names_;
};
SceneSpec* WorldTest::spec_ = nullptr;
robot::RobotDescription* WorldTest::robot_ = nullptr;
std::vector<toollib::ToolModel>* WorldTest::library_ = nullptr;
std::vector<std::string> WorldTest::names_;

// One source of truth: forward kinematics of the URDF equals MuJoCo's body poses.
TEST_F(WorldTest, UrdfKinematicsEqualsMujocoBodyPoses) {
  const ComposedScene scene = Compose(1);
  World world(scene.mjcf, "fk");
  ASSERT_EQ(world.actuated_joints(), robot_->model.JointNames());
  Rng rng(DeriveSeed(1, "fk_test"));
  constexpr double kTol = 1e-6;
  for (int trial = 0; trial < 100; ++trial) {
    Eigen::VectorXd q(robot_->model.num_q());
    for (int i = 0; i < q.size(); ++i) {
      const auto& joint = robot_->model.joints[robot_->model.movable_joints[i]];
      q[i] = UniformReal(rng, joint.lower, joint.upper);
    }
    world.TeleportJoints(q);
    ASSERT_TRUE(world.JointPositions().isApprox(q, 1e-12));
    const GroundTruth truth = world.ground_truth();
    const std::vector<Eigen::Isometry3d> X_RL = robot::LinkPoses(robot_->model, q);
    for (size_t l = 0; l < robot_->model.links.size(); ++l) {
      const Eigen::Isometry3d X_WL = scene.X_WR * X_RL[l];
      const Eigen::Isometry3d& X_WB = truth.Pose(robot_->model.links[l].name);
      ASSERT_LT((X_WL.translation() - X_WB.translation()).norm(), kTol) << robot_->model.links[l].name;
      ASSERT_LT((X_WL.linear() - X_WB.linear()).norm(), kTol) << robot_->model.links[l].name;
    }
  }
}

// Physics at rest holds still: after settling, tools drift < 1 mm in 2 s and the ball stays put,
// by the contact model alone (sleeping off).
TEST_F(WorldTest, ToolsAndBallStayPutAtRest) {
  const SceneSpec awake = Awake();
  for (std::uint64_t seed : {1, 2, 3, 4, 5, 6}) {
    const ComposedScene scene = Compose(seed, {}, &awake);
    World world(scene.mjcf, "rest");
    ASSERT_EQ(world.sleep_settings().window_s, 0.0);
    ASSERT_TRUE(world.SettleFreeBodies(spec_->physics.settle_time)) << "seed " << seed;
    const GroundTruth before = world.ground_truth();
    ASSERT_TRUE(world.Advance(2.0).ok) << world.status().message;
    const GroundTruth after = world.ground_truth();
    for (const auto& tool : scene.tools) {
      const double drift = (after.Pose(tool.body).translation() - before.Pose(tool.body).translation()).norm();
      EXPECT_LT(drift, 1e-3) << "seed " << seed << ": " << tool.name << " in " << tool.cell;
      // Still on the rack: not fallen to the floor.
      EXPECT_GT(after.Pose(tool.body).translation().z(), 0.3) << tool.name;
    }
    EXPECT_LT((after.Pose("ball").translation() - before.Pose("ball").translation()).norm(), 1e-3);
  }
}

// A round stick laid on the table and pushed across it stops within a few centimetres: the table top
// resists rolling (with no rolling friction there a stick put down beside the ball rolled on across
// the table and swept the ball off its far edge).
TEST_F(WorldTest, AStickPushedAcrossTheTableStopsRolling) {
  const SceneSpec awake = Awake();
  const ComposedScene scene = Compose(1, {{"stick_2", "pos2"}}, &awake);
  World world(scene.mjcf, "roll");
  const toollib::ToolModel* stick = nullptr;
  for (const auto& t : *library_) {
    if (t.name == "stick_2") stick = &t;
  }
  ASSERT_NE(stick, nullptr);
  const double length = stick->mesh.vertices.row(2).maxCoeff() - stick->mesh.vertices.row(2).minCoeff();
  const double radius = -stick->mesh.vertices.row(0).minCoeff();
  ASSERT_GT(radius, 0.005);
  // Lying across the table's centre, its axis (z_T) along y_R, 1 mm above the top.
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();
  X_RT.linear() = Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Vector3d center(spec_->table.center.x(), spec_->table.center.y(), spec_->table.top_z + radius + 0.001);
  X_RT.translation() = center - X_RT.linear() * Eigen::Vector3d(0, 0, length / 2);
  const std::string& body = scene.tools.front().body;
  world.TeleportFreeBody(body, scene.X_WR * X_RT);
  ASSERT_TRUE(world.Advance(0.3).ok);
  const Eigen::Vector3d start = world.ground_truth().Pose(body).translation();
  // A push of 0.4 m/s across its axis (toward the table's far edge, 25 cm away): it slides,
  // starts rolling, and without rolling resistance rolls on at ~0.27 m/s, off the table.
  const mjModel* m = world.mj_model();
  const int id = mj_name2id(m, mjOBJ_BODY, body.c_str());
  ASSERT_GE(id, 0);
  const Eigen::Vector3d push_W = scene.X_WR.linear() * Eigen::Vector3d(-0.4, 0.0, 0.0);
  const int dof = m->jnt_dofadr[m->body_jntadr[id]];
  for (int i = 0; i < 3; ++i) world.mj_data()->qvel[dof + i] = push_W[i];
  ASSERT_TRUE(world.Advance(1.5).ok) << world.status().message;
  const Eigen::Vector3d end = world.ground_truth().Pose(body).translation();
  EXPECT_LT((end - start).norm(), 0.1) << "the stick rolled on";
  EXPECT_NEAR(end.z(), start.z(), 0.005) << "the stick left the table";
  const double speed = Eigen::Map<const Eigen::Vector3d>(world.mj_data()->qvel + dof).norm();
  EXPECT_LT(speed, 0.01) << "still moving";
}

// Resting tools and the ball fall asleep (out of the contact solve, held exactly), and a body that
// comes near wakes them: a ball dropped onto a sleeping tool lying across the rack lands on it.
TEST_F(WorldTest, RestingBodiesSleepAndWakeWhenSomethingComesNear) {
  const ComposedScene scene = Compose(2, {{"hoe_1", "rot3"}});
  World world(scene.mjcf, "sleep");
  ASSERT_GT(world.sleep_settings().window_s, 0.0);
  const std::string tool = scene.tools[0].body;
  ASSERT_TRUE(world.SettleFreeBodies(spec_->physics.settle_time));
  world.Advance(2.0 * world.sleep_settings().window_s);
  ASSERT_TRUE(world.IsAsleep(tool));
  ASSERT_TRUE(world.IsAsleep("ball"));
  EXPECT_EQ(world.num_contacts(), 0);  // the robot touches nothing; the sleepers leave the solve
  const PhysicsStats before = world.physics_stats();
  const Eigen::Isometry3d X_WT = world.ground_truth().Pose(tool);
  world.Advance(1.0);
  const PhysicsStats slept = world.physics_stats() - before;
  EXPECT_EQ(slept.asleep, 2 * slept.steps);
  EXPECT_EQ(slept.contacts, 0);
  EXPECT_EQ(slept.solver_iterations, 0);  // nothing to solve
  EXPECT_TRUE(world.ground_truth().Pose(tool).isApprox(X_WT, 0.0));  // held exactly
  EXPECT_THROW(world.IsAsleep("table"), std::invalid_argument);

  // Drop the ball 10 cm above the tool's centre of mass: it wakes the tool and lands on it.
  Eigen::Vector3d com;
  {
    const mjModel* m = world.mj_model();
    const int id = mj_name2id(m, mjOBJ_BODY, tool.c_str());
    com = Eigen::Map<const Eigen::Vector3d>(world.mj_data()->xipos + 3 * id);
  }
  Eigen::Isometry3d X_WB = Eigen::Isometry3d::Identity();
  X_WB.translation() = com + Eigen::Vector3d(0, 0, 0.10 + spec_->ball.radius);
  world.TeleportFreeBody("ball", X_WB);
  EXPECT_FALSE(world.IsAsleep("ball"));
  bool woke = false, touched = false;
  for (int i = 0; i < 250 && !touched; ++i) {
    world.Step();
    woke = woke || !world.IsAsleep(tool);
    const std::vector<std::string> bodies = world.ContactingBodies("ball");
    touched = std::find(bodies.begin(), bodies.end(), tool) != bodies.end();
  }
  EXPECT_TRUE(woke);
  EXPECT_TRUE(touched) << "the ball fell through the tool";
  // The landing is solved (the tool rests on the rack, so the noslip pass runs and its iterations
  // count too: noslip_iterations a step).
  const PhysicsStats landed = world.physics_stats() - before;
  EXPECT_GE(landed.solver_iterations, spec_->physics.noslip_iterations);
  EXPECT_TRUE(world.status().ok) << world.status().message;
}

// A sleeper wakes when a mover comes within the wake margin of its box, not of its bounding
// sphere: a long tool's sphere is as wide as the tool is long (carried past its neighbours on the
// rack, a tool kept them awake, and the noslip pass on, for seconds).
TEST_F(WorldTest, ASleeperWakesNearItsBoxNotAnywhereInItsBoundingSphere) {
  const ComposedScene scene = Compose(2, {{"lstick_1", "rot0"}});
  World world(scene.mjcf, "sleep, box");
  const std::string tool = scene.tools[0].body;
  ASSERT_TRUE(world.SettleFreeBodies(spec_->physics.settle_time));
  world.Advance(2.0 * world.sleep_settings().window_s);
  ASSERT_TRUE(world.IsAsleep(tool));
  // The tool's mesh geom: its box in the geom frame from the mesh's vertices, and the box axis
  // along which it is thinnest.
  const mjModel* m = world.mj_model();
  const mjData* d = world.mj_data();
  const int body = mj_name2id(m, mjOBJ_BODY, tool.c_str());
  int g = -1;  // the mesh; the tool's other geoms (primitive pieces of its shape) lie inside it
  for (int k = 0; k < m->body_geomnum[body] && g < 0; ++k) {
    if (m->geom_type[m->body_geomadr[body] + k] == mjGEOM_MESH) g = m->body_geomadr[body] + k;
  }
  ASSERT_GE(g, 0);
  const int mesh = m->geom_dataid[g];
  const Eigen::Map<const Eigen::Matrix3Xf> v(m->mesh_vert + 3 * m->mesh_vertadr[mesh], 3, m->mesh_vertnum[mesh]);
  const Eigen::Vector3d lo = v.rowwise().minCoeff().cast<double>();
  const Eigen::Vector3d hi = v.rowwise().maxCoeff().cast<double>();
  const Eigen::Vector3d half = 0.5 * (hi - lo);
  int thin = 0;
  half.minCoeff(&thin);
  const Eigen::Matrix3d R = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(d->geom_xmat + 9 * g);
  const Eigen::Vector3d centre = Eigen::Map<const Eigen::Vector3d>(d->geom_xpos + 3 * g) + R * (0.5 * (lo + hi));
  // Above (or below) the thin side: the ball put there falls toward the tool, or away from it.
  const Eigen::Vector3d side = R.col(thin).z() >= 0 ? R.col(thin) : Eigen::Vector3d(-R.col(thin));
  const double r = spec_->ball.radius;
  const double margin = world.sleep_settings().wake_margin_m;
  auto put_ball = [&](double gap) {
    Eigen::Isometry3d X_WB = Eigen::Isometry3d::Identity();
    X_WB.translation() = centre + (half[thin] + r + gap) * side;
    world.TeleportFreeBody("ball", X_WB);
    world.Step();
  };
  const double far_gap = 3.0 * margin;
  ASSERT_LT(half[thin] + r + far_gap, m->geom_rbound[g] + r + margin) << "not inside the bounding sphere";
  put_ball(far_gap);
  EXPECT_TRUE(world.IsAsleep(tool)) << "woken by a ball " << far_gap << " m from its box";
  put_ball(0.5 * margin);
  EXPECT_FALSE(world.IsAsleep(tool)) << "not woken by a ball " << 0.5 * margin << " m from its box";
}

// The default scene runs the noslip pass only while a tool rests awake on the rack (noslip_scope
// "resting") and stiffens the robot's contacts instead: tools awake on the rack hold still as with
// the pass at every step, and once everything sleeps no step runs it.
TEST_F(WorldTest, NoslipRunsOnlyWhileAToolRestsAwakeOnTheRack) {
  ASSERT_EQ(spec_->physics.noslip_scope, "resting");
  SceneSpec awake = *spec_;
  awake.physics.sleep_window = 0.0;
  for (std::uint64_t seed : {1, 2, 3, 4, 5, 6}) {
    const ComposedScene scene = Compose(seed, {}, &awake);
    World world(scene.mjcf, "resting, awake");
    ASSERT_TRUE(world.SettleFreeBodies(awake.physics.settle_time)) << "seed " << seed;
    const GroundTruth before = world.ground_truth();
    const PhysicsStats stats_before = world.physics_stats();
    ASSERT_TRUE(world.Advance(2.0).ok) << world.status().message;
    const PhysicsStats rested = world.physics_stats() - stats_before;
    EXPECT_EQ(rested.noslip_steps, rested.steps) << "seed " << seed;  // the tools touch the rack
    const GroundTruth after = world.ground_truth();
    for (const auto& tool : scene.tools) {
      const double drift = (after.Pose(tool.body).translation() - before.Pose(tool.body).translation()).norm();
      EXPECT_LT(drift, 1e-3) << "seed " << seed << ": " << tool.name << " in " << tool.cell;
    }
  }
  // Asleep, nothing rests on the rack in the contact solve: no step runs the pass, where
  // scenes/noslip_always.json ("always") runs it at every step.
  const SceneSpec always = LoadSceneSpec(ScenesDir() / "noslip_always.json");
  ASSERT_EQ(always.physics.noslip_scope, "always");
  for (const SceneSpec* spec : {static_cast<const SceneSpec*>(spec_), &always}) {
    const ComposedScene scene = Compose(2, {{"hoe_1", "rot3"}}, spec);
    World world(scene.mjcf, spec->name);
    ASSERT_TRUE(world.SettleFreeBodies(spec->physics.settle_time));
    world.Advance(2.0 * world.sleep_settings().window_s);
    ASSERT_TRUE(world.IsAsleep(scene.tools[0].body));
    const PhysicsStats before = world.physics_stats();
    world.Advance(0.5);
    const PhysicsStats slept = world.physics_stats() - before;
    EXPECT_EQ(slept.noslip_steps, spec == &always ? slept.steps : 0) << spec->name;
  }
}

TEST_F(WorldTest, EveryCellSettlesOnTheRack) {
  // Table 5.3 cells for every tool: after settling the tool rests on the rack (not the floor)
  // and then holds still.
  for (const auto& tool : *library_) {
    for (std::string_view cell_view : kCellNames) {
      const std::string cell(cell_view);
      const ComposedScene scene = Compose(1, {{tool.name, cell}});
      World world(scene.mjcf, "cell");
      EXPECT_TRUE(world.SettleFreeBodies(spec_->physics.settle_time)) << tool.name << " " << cell << " never comes to rest";
      const Eigen::Vector3d p0 = world.ground_truth().Pose(scene.tools[0].body).translation();
      world.Advance(1.0);
      const Eigen::Vector3d p1 = world.ground_truth().Pose(scene.tools[0].body).translation();
      EXPECT_LT((p1 - p0).norm(), 1e-3) << tool.name << " in " << cell << " still moves";
      EXPECT_GT(p1.z(), 0.3) << tool.name << " in " << cell << " fell off the rack";
    }
  }
}

TEST_F(WorldTest, SameSeedSameTrajectoryBitForBit) {
  auto run = [&] {
    World world(Compose(9).mjcf, "det");
    Eigen::VectorXd target = world.JointTargets();
    target[0] += 0.3;
    world.SetJointTargets(target);
    world.Advance(0.5);
    return Eigen::Map<const Eigen::VectorXd>(world.mj_data()->qpos, world.mj_model()->nq).eval();
  };
  const Eigen::VectorXd a = run();
  const Eigen::VectorXd b = run();
  EXPECT_EQ((a - b).cwiseAbs().maxCoeff(), 0.0);
}

TEST_F(WorldTest, ServosHoldHomeAgainstGravity) {
  World world(Compose(1).mjcf, "servo");
  const Eigen::VectorXd home = world.JointTargets();
  world.Advance(1.0);
  const Eigen::VectorXd error = (world.JointPositions() - home).cwiseAbs();
  EXPECT_LT(error.maxCoeff(), 1.5 * M_PI / 180.0) << error.transpose();
}

TEST(SimRobotTest, WaitThrowsOnceThePhysicsIsUnstable) {
  // A stiff servo on a feather-light link with a coarse step: the integration blows up, MuJoCo
  // stops advancing time, and a motion waiting for the encoders would wait forever.
  const std::string mjcf = R"(<mujoco><option timestep="0.01"/><worldbody><body>
      <joint name="j" type="hinge"/><geom type="capsule" size="0.01 0.1" mass="1e-6"/></body></worldbody>
      <actuator><position joint="j" kp="1e9"/></actuator></mujoco>)";
  World world(mjcf, "unstable");
  SimRobot robot(world);
  robot.SetPositionTargets(Eigen::VectorXd::Constant(1, 1.0));
  EXPECT_THAT([&] { robot.Wait(1.0); }, ThrowsMessage<std::runtime_error>(HasSubstr("simulation unstable")));
  EXPECT_FALSE(world.status().ok);
}

// Too little room for the contacts or constraint rows of a step stops the simulation and names
// the scene field to raise; MuJoCo alone would drop the contacts that do not fit and go on.
TEST_F(WorldTest, AStepWithMoreContactsThanThereIsRoomForStopsNamingTheField) {
  // The default room holds a three-tool scene's contacts as it settles (awake: sleepers leave
  // the contact solve).
  const std::vector<ToolPlacement> three = {{"hoe_1", "pos1"}, {"rake_2", "pos2"}, {"stick_1", "pos3"}};
  const SceneSpec awake = Awake();
  World roomy(Compose(3, three, &awake).mjcf, "roomy");
  roomy.Advance(0.5);
  EXPECT_TRUE(roomy.status().ok) << roomy.status().message;
  EXPECT_GT(roomy.num_contacts(), 2);

  // Room for 2 contacts, then for 8 constraint rows.
  const std::pair<int PhysicsSpec::*, int> tight[] = {{&PhysicsSpec::max_contacts, 2},
                                                      {&PhysicsSpec::max_constraint_rows, 8}};
  const char* field[] = {"physics.max_contacts", "physics.max_constraint_rows"};
  for (int k = 0; k < 2; ++k) {
    SceneSpec spec = *spec_;
    spec.physics.*tight[k].first = tight[k].second;
    World world(Compose(3, three, &spec).mjcf, field[k]);
    world.Advance(0.5);
    EXPECT_FALSE(world.status().ok) << field[k];
    EXPECT_THAT(world.status().message, HasSubstr(field[k]));
  }
}

TEST_F(WorldTest, BadTargetsAreRejected) {
  World world(Compose(1).mjcf, "bad");
  EXPECT_THAT([&] { world.SetJointTargets(Eigen::VectorXd::Zero(2)); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("actuated joints")));
  Eigen::VectorXd nan = world.JointTargets();
  nan[0] = NAN;
  EXPECT_THAT([&] { world.SetJointTargets(nan); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("non-finite")));
  EXPECT_THAT([&] { world.ResetToKeyframe("nope"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("nope")));
}

}  // namespace
}  // namespace toolbench::sim
