#include "sim/scene_spec.h"

#include <utility>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench::sim {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

TEST(SceneSpecTest, DefaultFileParses) {
  const SceneSpec spec = LoadSceneSpec(DefaultScenePath());
  EXPECT_EQ(spec.name, "default");
  EXPECT_DOUBLE_EQ(spec.physics.timestep, 0.002);
}

TEST(SceneSpecTest, EmptyObjectGivesDefaults) {
  const SceneSpec spec = ParseSceneSpec("{}", "inline");
  EXPECT_EQ(spec.robot, "robots/icub_upper_body.json");
  EXPECT_EQ(spec.tools.max_count, 3);
}

// scenes/README.md promises that a field left out of a scene file takes scenes/default.json's
// value: the file and the code's defaults are the same scene.
TEST(SceneSpecTest, TheDefaultFileSpellsOutTheDefaults) {
  const SceneSpec file = LoadSceneSpec(DefaultScenePath());
  const SceneSpec defaults = ParseSceneSpec("{}", "inline");
  EXPECT_TRUE(file.table == defaults.table);
  EXPECT_TRUE(file.ball == defaults.ball);
  EXPECT_TRUE(file.rack == defaults.rack);
  EXPECT_TRUE(file.tools == defaults.tools);
  EXPECT_TRUE(file.physics == defaults.physics);
  EXPECT_TRUE(file == defaults);
}

TEST(SceneSpecTest, OverridesFields) {
  const SceneSpec spec = ParseSceneSpec(
      R"({"rack": {"incline_deg": 20}, "ball": {"radius": 0.04}, "tools": {"choices": ["hoe_1"]},
          "physics": {"noslip_tolerance": 1e-4, "solver": "CG", "jacobian": "sparse", "tolerance": 1e-6,
                      "iterations": 50, "robot_solimp": [0.95, 0.99, 0.002], "robot_solmix": 10,
                      "max_contacts": 40, "max_constraint_rows": 300}})",
      "inline");
  EXPECT_EQ(spec.physics.max_contacts, 40);
  EXPECT_EQ(spec.physics.max_constraint_rows, 300);
  EXPECT_DOUBLE_EQ(spec.physics.noslip_tolerance, 1e-4);
  EXPECT_EQ(spec.physics.robot_solimp, Eigen::Vector3d(0.95, 0.99, 0.002));
  EXPECT_DOUBLE_EQ(spec.physics.robot_solmix, 10);
  EXPECT_DOUBLE_EQ(spec.physics.tolerance, 1e-6);
  EXPECT_EQ(spec.physics.iterations, 50);
  EXPECT_EQ(spec.physics.solver, "CG");
  EXPECT_EQ(spec.physics.jacobian, "sparse");
  EXPECT_DOUBLE_EQ(spec.rack.incline_deg, 20);
  EXPECT_DOUBLE_EQ(spec.ball.radius, 0.04);
  EXPECT_EQ(spec.tools.choices, std::vector<std::string>{"hoe_1"});
}

TEST(SceneSpecTest, MalformedInputNamesSourceAndField) {
  EXPECT_THAT([] { ParseSceneSpec("{\"rack\": ", "bad.json"); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("bad.json"), HasSubstr("not valid JSON"))));
  EXPECT_THAT([] { ParseSceneSpec(R"({"rack": {"inclne_deg": 3}})", "typo.json"); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("typo.json"), HasSubstr("rack.inclne_deg"))));
  EXPECT_THAT([] { ParseSceneSpec(R"({"ball": {"radius": "big"}})", "type.json"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("ball.radius' must be a number")));
  EXPECT_THAT([] { ParseSceneSpec(R"({"ball": {"radius": -1}})", "range.json"); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("range.json"), HasSubstr("ball.radius"))));
  EXPECT_THAT([] { ParseSceneSpec(R"({"robot_base": [0, 0]})", "size.json"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("array of 3 numbers")));
  // A physics field out of its range: the message names the scene and the field.
  const std::pair<const char*, const char*> out_of_range[] = {
      {R"({"noslip_tolerance": 0})", "physics.noslip_tolerance"},
      {R"({"noslip_scope": "sometimes"})", "physics.noslip_scope"},
      {R"({"robot_solimp": [0.99, 1.0, 0.001]})", "physics.robot_solimp"},
      {R"({"robot_solimp": [0.99, 0.999, 0]})", "physics.robot_solimp"},
      {R"({"robot_solmix": 0})", "physics.robot_solmix"},
      {R"({"tolerance": -1e-6})", "physics.tolerance"},
      {R"({"iterations": 0})", "physics.iterations"},
      {R"({"max_contacts": 0})", "physics.max_contacts"},
      {R"({"max_constraint_rows": -5})", "physics.max_constraint_rows"},
      {R"({"sleep_window": -1})", "physics.sleep_window"},
      {R"({"wake_margin": 0})", "physics.wake_margin"},
  };
  for (const auto& [physics, field] : out_of_range) {
    const std::string text = std::string(R"({"physics": )") + physics + "}";
    EXPECT_THAT([&] { ParseSceneSpec(text, "physics.json"); },
                ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("physics.json"), HasSubstr(field))))
        << physics;
  }
  EXPECT_THAT([] { ParseSceneSpec(R"({"physics": {"robot_solimp": [0.99, 0.999]}})", "imp.json"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("array of 3 numbers")));
  EXPECT_THAT([] { ParseSceneSpec(R"({"physics": {"cone": "round"}})", "cone.json"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("round")));
  EXPECT_THAT([] { ParseSceneSpec(R"({"physics": {"solver": "Gauss"}})", "solver.json"); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("physics.solver"), HasSubstr("Gauss"))));
  EXPECT_THAT([] { ParseSceneSpec(R"({"physics": {"jacobian": "banded"}})", "jac.json"); },
              ThrowsMessage<std::invalid_argument>(AllOf(HasSubstr("physics.jacobian"), HasSubstr("banded"))));
  EXPECT_THAT([] { ParseSceneSpec("[1, 2]", "array.json"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("must be an object")));
  EXPECT_THAT([] { LoadSceneSpec("/nonexistent/scene.json"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("/nonexistent/scene.json")));
}

}  // namespace
}  // namespace toolbench::sim
