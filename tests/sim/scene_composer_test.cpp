#include "sim/scene_composer.h"

#include <algorithm>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include "common/paths.h"
#include "sim/world.h"

namespace toolbench::sim {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

class ComposerTest : public ::testing::Test {
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
  static SceneSpec* spec_;
  static robot::RobotDescription* robot_;
  static std::vector<toollib::ToolModel>* library_;
  static std::vector<std::string> names_;
};
SceneSpec* ComposerTest::spec_ = nullptr;
robot::RobotDescription* ComposerTest::robot_ = nullptr;
std::vector<toollib::ToolModel>* ComposerTest::library_ = nullptr;
std::vector<std::string> ComposerTest::names_;

TEST_F(ComposerTest, SameSeedSamePlanOtherSeedOtherPlan) {
  const ScenePlan a = PlanScene(*spec_, names_, 11, {});
  const ScenePlan b = PlanScene(*spec_, names_, 11, {});
  ASSERT_EQ(a.tools.size(), b.tools.size());
  for (size_t i = 0; i < a.tools.size(); ++i) {
    EXPECT_EQ(a.tools[i].tool, b.tools[i].tool);
    EXPECT_EQ(a.tools[i].cell, b.tools[i].cell);
    EXPECT_EQ(a.tools[i].offset, b.tools[i].offset);
  }
  EXPECT_EQ(a.ball_xy, b.ball_xy);
  // Some other seed changes the tools or their placement.
  bool differs = false;
  for (std::uint64_t seed = 12; seed < 20 && !differs; ++seed) {
    const ScenePlan c = PlanScene(*spec_, names_, seed, {});
    differs = c.tools.size() != a.tools.size() || c.tools[0].tool != a.tools[0].tool ||
              c.tools[0].offset != a.tools[0].offset;
  }
  EXPECT_TRUE(differs);
}

TEST_F(ComposerTest, RandomPlansRespectCountsAndPlaces) {
  for (std::uint64_t seed = 0; seed < 50; ++seed) {
    const ScenePlan plan = PlanScene(*spec_, names_, seed, {});
    ASSERT_GE(plan.tools.size(), 1u);
    ASSERT_LE(plan.tools.size(), 3u);
    for (const auto& p : plan.tools) EXPECT_TRUE(IsCellName(p.cell)) << p.cell;
    EXPECT_GE(plan.ball_xy.x(), spec_->ball.x_range[0]);
    EXPECT_LE(plan.ball_xy.x(), spec_->ball.x_range[1]);
  }
}

TEST_F(ComposerTest, BadRequestsNameTheInput) {
  EXPECT_THAT([&] { PlanScene(*spec_, names_, 1, {{"spoon_9", "pos1"}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("unknown tool 'spoon_9'")));
  EXPECT_THAT([&] { PlanScene(*spec_, names_, 1, {{names_[0], "pos7"}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("unknown cell 'pos7'")));
  EXPECT_THAT([&] { PlanScene(*spec_, names_, 1, {{names_[0], "rot1"}, {names_[1], "pos2"}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("pos2")));
}

TEST_F(ComposerTest, CellPosesFollowTable53) {
  const RackSpec& rack = spec_->rack;
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  EXPECT_TRUE((CellPose(rack, "rot0").linear() * z).isApprox(z));
  EXPECT_TRUE((CellPose(rack, "rot1").linear() * x).isApprox(Eigen::Vector3d::UnitY()));  // toward robot
  EXPECT_TRUE((CellPose(rack, "rot2").linear() * z).isApprox(-z));                        // upside down
  EXPECT_TRUE((CellPose(rack, "rot3").linear() * z).isApprox(-x));                        // across
  EXPECT_TRUE((CellPose(rack, "rot3").linear() * x).isApprox(z));                         // effector up
  EXPECT_NEAR(CellPose(rack, "pos1").translation().x(), rack.slot_pos1, 1e-12);
  // The rack faces the robot: its normal y_K points toward the robot's midline (-y_R).
  EXPECT_LT(RackPose(rack).linear().col(1).dot(rack.origin.normalized()), -0.8);
}

TEST_F(ComposerTest, ExtendedCellsCombineAPlaceWithARotation) {
  const RackSpec& rack = spec_->rack;
  for (const char* place : {"pos1", "pos2", "pos3"}) {
    for (const char* rotation : {"rot0", "rot1", "rot2", "rot3"}) {
      const std::string cell = std::string(place) + "_" + rotation;
      EXPECT_TRUE(IsCellName(cell)) << cell;
      const Eigen::Isometry3d X = CellPose(rack, cell);
      EXPECT_TRUE(X.linear().isApprox(CellPose(rack, rotation).linear())) << cell;
      EXPECT_NEAR(X.translation().x(), CellPose(rack, place).translation().x(), 1e-12) << cell;
    }
  }
  EXPECT_EQ(std::size(kExtendedCellNames), 12u);
  // Every tool fits the rack alone in every extended cell (table53 --extended runs them all).
  for (const auto& tool : *library_) {
    for (std::string_view cell : kExtendedCellNames) {
      const ScenePlan plan = PlanScene(*spec_, names_, 3, {{tool.name, std::string(cell)}});
      EXPECT_NO_THROW(ComposeScene(*spec_, *robot_, *library_, plan)) << tool.name << " " << cell;
    }
  }
  EXPECT_FALSE(IsCellName("pos4_rot1"));
  EXPECT_FALSE(IsCellName("pos1_rot"));
  EXPECT_THAT([&] { CellPose(rack, "pos1_rot9"); }, ThrowsMessage<std::invalid_argument>(HasSubstr("pos1_rot9")));
  // Two extended cells at one place are two tools in one place.
  EXPECT_THAT([&] { PlanScene(*spec_, names_, 1, {{names_[0], "pos1_rot1"}, {names_[1], "pos1_rot2"}}); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("pos1")));
}

TEST_F(ComposerTest, EveryToolInEveryCellComposesAndLoads) {
  // One tool per scene keeps this fast; placements must put every tool on the ledge in front of
  // the board (z_K >= 0, y_K >= 0 for all its geometry).
  for (const auto& tool : *library_) {
    for (const char* cell : {"pos1", "rot1", "rot2", "rot3"}) {
      const ScenePlan plan = PlanScene(*spec_, names_, 3, {{tool.name, cell}});
      const ComposedScene scene = ComposeScene(*spec_, *robot_, *library_, plan);
      ASSERT_EQ(scene.tools.size(), 1u);
      const Eigen::Isometry3d X_KT = scene.X_RK.inverse() * scene.tools[0].X_RT;
      const Eigen::Matrix3Xd p_K = (X_KT.linear() * tool.mesh.vertices).colwise() + X_KT.translation();
      EXPECT_GT(p_K.row(1).minCoeff(), 0.0) << tool.name << " " << cell << " intersects the board";
      EXPECT_GT(p_K.row(2).minCoeff(), 0.0) << tool.name << " " << cell << " intersects the ledge";
      EXPECT_LT(p_K.row(1).minCoeff(), spec_->rack.standoff + 0.01) << tool.name << " " << cell << " floats off the rack";
    }
  }
  const ScenePlan plan = PlanScene(*spec_, names_, 5, {});
  EXPECT_NO_THROW(World(ComposeScene(*spec_, *robot_, *library_, plan).mjcf, "seed 5"));
}

// One source of truth: the fixture boxes the planner avoids are the geoms the physics collides with.
TEST_F(ComposerTest, FixtureBoxesAreTheComposedGeoms) {
  const ComposedScene scene = ComposeScene(*spec_, *robot_, *library_, PlanScene(*spec_, names_, 3, {}));
  World world(scene.mjcf, "fixtures");
  const mjModel* m = world.mj_model();
  mjData* d = world.mj_data();
  mj_kinematics(m, d);
  const std::vector<FixtureBox> boxes = FixtureBoxes(*spec_);
  std::vector<std::string> names;
  for (const FixtureBox& box : boxes) names.push_back(box.name);
  for (const char* expected : {"table_top", "table_leg0", "rack_board", "rack_ledge", "rack_rail", "rack_post1"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
  }
  for (const FixtureBox& box : boxes) {
    const int id = mj_name2id(m, mjOBJ_GEOM, box.name.c_str());
    ASSERT_GE(id, 0) << box.name;
    EXPECT_EQ(m->geom_type[id], mjGEOM_BOX) << box.name;
    const Eigen::Isometry3d X_WB = scene.X_WR * box.X_RB;
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(m->geom_size[3 * id + k], box.half[k], 1e-9) << box.name;
      EXPECT_NEAR(d->geom_xpos[3 * id + k], X_WB.translation()[k], 1e-7) << box.name;
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(d->geom_xmat[9 * id + 3 * k + c], X_WB.linear()(k, c), 1e-7) << box.name;
    }
  }
}

// The scene's physics settings reach the compiled model (the solver's settings decide how fast a
// step is and how well a grasp holds).
TEST_F(ComposerTest, PhysicsSettingsReachTheModel) {
  SceneSpec spec = *spec_;
  spec.physics.solver = "CG";
  spec.physics.jacobian = "sparse";
  spec.physics.noslip_iterations = 7;
  spec.physics.tolerance = 1e-6;
  spec.physics.iterations = 40;
  spec.physics.robot_solimp = {0.95, 0.99, 0.002};
  spec.physics.robot_solmix = 50;
  World world(ComposeScene(spec, *robot_, *library_, PlanScene(spec, names_, 3, {})).mjcf, "physics");
  const mjModel* m = world.mj_model();
  EXPECT_EQ(m->opt.solver, mjSOL_CG);
  EXPECT_EQ(m->opt.jacobian, mjJAC_SPARSE);
  EXPECT_EQ(m->opt.noslip_iterations, 7);
  EXPECT_DOUBLE_EQ(m->opt.tolerance, 1e-6);
  EXPECT_EQ(m->opt.iterations, 40);
  EXPECT_EQ(m->opt.cone, mjCONE_ELLIPTIC);
  // Every robot collision geom (and only those) has the robot's contact impedance.
  int robot_geoms = 0;
  for (int g = 0; g < m->ngeom; ++g) {
    const bool robot = m->geom_contype[g] == 1 && m->geom_conaffinity[g] == 0;
    if (!robot) {
      EXPECT_DOUBLE_EQ(m->geom_solmix[g], 1.0) << g;
      continue;
    }
    ++robot_geoms;
    EXPECT_DOUBLE_EQ(m->geom_solmix[g], 50.0) << g;
    for (int k = 0; k < 3; ++k) EXPECT_DOUBLE_EQ(m->geom_solimp[mjNIMP * g + k], spec.physics.robot_solimp[k]) << g;
  }
  EXPECT_GT(robot_geoms, 15);
}

TEST_F(ComposerTest, FixedCamerasAreWhereTheSceneSaysTheyAre) {
  const ComposedScene scene = ComposeScene(*spec_, *robot_, *library_, PlanScene(*spec_, names_, 3, {}));
  World world(scene.mjcf, "cameras");
  const mjModel* m = world.mj_model();
  mjData* d = world.mj_data();
  mj_kinematics(m, d);
  ASSERT_EQ(scene.X_R_fixed_cameras.size(), 3u);
  for (const char* name : {"overview", "side", "rack_close"}) {
    ASSERT_TRUE(scene.X_R_fixed_cameras.count(name)) << name;
    const int id = mj_name2id(m, mjOBJ_CAMERA, name);
    ASSERT_GE(id, 0) << name;
    // The OpenCV optical frame is MuJoCo's camera frame turned by pi about x.
    const Eigen::Isometry3d X_WC = scene.X_WR * scene.X_R_fixed_cameras.at(name);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(d->cam_xpos[3 * id + k], X_WC.translation()[k], 1e-7) << name;
      EXPECT_NEAR(d->cam_xmat[9 * id + 3 * k + 0], X_WC.linear()(k, 0), 1e-6) << name;
      EXPECT_NEAR(d->cam_xmat[9 * id + 3 * k + 1], -X_WC.linear()(k, 1), 1e-6) << name;
      EXPECT_NEAR(d->cam_xmat[9 * id + 3 * k + 2], -X_WC.linear()(k, 2), 1e-6) << name;
    }
  }
}

TEST_F(ComposerTest, BrokenMjcfIsReportedWithSource) {
  EXPECT_THAT([] { World("<mujoco><worldbody><geom type='box'/></worldbody>", "broken.xml"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("broken.xml")));
}

}  // namespace
}  // namespace toolbench::sim
