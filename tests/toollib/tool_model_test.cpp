#include "toollib/tool_model.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/paths.h"
#include "tests/toollib/test_util.h"
#include "toollib/mesh.h"

namespace toolbench::toollib {
namespace {

using ::testing::AllOf;
using testing::FreshTempDir;
using ::testing::HasSubstr;
using testing::MeshData;
using ::testing::ThrowsMessage;

constexpr double kTol = 1e-12;

TEST(ToolModelTest, LoadsUserSidecarWithoutCollisionAsOneMeshPart) {
  const ToolModel tool = LoadToolModel(MeshData("sidecars/user_cube.json"));
  EXPECT_EQ(tool.name, "user_cube");
  EXPECT_EQ(tool.family, "custom");
  EXPECT_DOUBLE_EQ(tool.mass, 0.2);
  EXPECT_TRUE(tool.mesh_file.is_absolute());
  EXPECT_EQ(tool.mesh_file.filename(), "cube_binary.stl");
  EXPECT_EQ(tool.mesh.faces.cols(), 12);
  EXPECT_NEAR(tool.total_length, 0.1, 1e-6);
  EXPECT_TRUE(tool.handle.axis.isApprox(Eigen::Vector3d::UnitZ()));
  EXPECT_EQ(tool.symmetries, std::vector<std::string>{"rot_z_90"});
  EXPECT_DOUBLE_EQ(tool.params.at("side"), 0.1);
  ASSERT_EQ(tool.collision.size(), 1u);
  EXPECT_EQ(tool.collision[0].type, CollisionPart::Type::kMesh);
  EXPECT_EQ(tool.collision[0].mesh_file, "../cube_binary.stl");
  EXPECT_DOUBLE_EQ(tool.collision[0].mass, 0.2);
}

struct BadSidecar {
  const char* file;
  const char* problem;
};

void PrintTo(const BadSidecar& bad, std::ostream* out) { *out << bad.file; }

class BadSidecarTest : public ::testing::TestWithParam<BadSidecar> {};

TEST_P(BadSidecarTest, ThrowsNamingFileAndField) {
  const auto path = MeshData(std::string("sidecars/") + GetParam().file);
  EXPECT_THAT([&] { LoadToolModel(path); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr(GetParam().file), HasSubstr(GetParam().problem))));
}

INSTANTIATE_TEST_SUITE_P(
    Sidecars, BadSidecarTest,
    ::testing::Values(BadSidecar{"missing_mass.json", "field 'mass': missing"},
                      BadSidecar{"unknown_family.json", "field 'family': unknown family 'spoon'"},
                      BadSidecar{"bad_axis_type.json", "field 'handle.axis': expected an array"},
                      BadSidecar{"mm_mesh.json", "looks like millimetres"}),
    [](const ::testing::TestParamInfo<BadSidecar>& info) {
      std::string name = info.param.file;
      std::replace_if(
          name.begin(), name.end(), [](unsigned char c) { return !std::isalnum(c); }, '_');
      return name;
    });

// Writes a sidecar variant of user_cube.json into `dir` after `edit`.
template <typename Edit>
std::filesystem::path WriteVariant(const std::filesystem::path& dir, const std::string& name,
                                   Edit edit) {
  nlohmann::json j = nlohmann::json::parse(ReadTextFile(MeshData("sidecars/user_cube.json")));
  j["name"] = name;
  j["mesh"] = MeshData("cube_binary.stl").string();  // absolute: the variant lives elsewhere
  edit(j);
  const auto path = dir / (name + ".json");
  WriteTextFile(path, j.dump(2));
  return path;
}

TEST(ToolModelTest, RejectsIllFormedFields) {
  const auto dir = FreshTempDir();
  const auto expect_throw = [&](const std::string& name, auto edit, const std::string& problem) {
    const auto path = WriteVariant(dir, name, edit);
    EXPECT_THAT([&] { LoadToolModel(path); }, ThrowsMessage<std::invalid_argument>(AllOf(
                                                  HasSubstr(name + ".json"), HasSubstr(problem))));
  };
  using nlohmann::json;
  expect_throw(
      "neg_mass", [](json& j) { j["mass"] = -1.0; }, "field 'mass': must be > 0");
  expect_throw(
      "short_center",
      [](json& j) {
        j["effector"]["center"] = {0.0, 1.0};
      },
      "field 'effector.center': expected an array of 3 numbers");
  expect_throw(
      "not_unit",
      [](json& j) {
        j["handle"]["axis"] = {0.0, 0.0, 2.0};
      },
      "field 'handle.axis': must be a unit vector");
  expect_throw(
      "far_handle",
      [](json& j) {
        j["handle"]["center"] = {0.0, 0.0, 1.0};
      },
      "field 'handle.center': lies outside");
  expect_throw(
      "bad_length", [](json& j) { j["total_length"] = 0.3; }, "field 'total_length'");
  expect_throw(
      "no_mesh_file", [](json& j) { j["mesh"] = "nowhere.stl"; }, "field 'mesh'");
  expect_throw(
      "sym_type",
      [](json& j) {
        j["symmetries"] = {1, 2};
      },
      "field 'symmetries[0]': expected a string");
  expect_throw(
      "bad_part_type",
      [](json& j) {
        j["collision"] = {{{"type", "cone"},
                           {"size", {0.1, 0.1, 0.1}},
                           {"pos", {0, 0, 0}},
                           {"quat", {1, 0, 0, 0}},
                           {"mass", 0.2}}};
      },
      "field 'collision[0].type': unknown collision type 'cone'");
  expect_throw(
      "mass_sum",
      [](json& j) {
        j["collision"] = {{{"type", "box"},
                           {"size", {0.05, 0.05, 0.05}},
                           {"pos", {0.05, 0.05, 0.05}},
                           {"quat", {1, 0, 0, 0}},
                           {"mass", 0.1}}};
      },
      "field 'collision': part masses sum to 0.1 kg but mass is 0.2 kg");
  expect_throw(
      "bad_quat",
      [](json& j) {
        j["collision"] = {{{"type", "box"},
                           {"size", {0.05, 0.05, 0.05}},
                           {"pos", {0.05, 0.05, 0.05}},
                           {"quat", {1, 1, 0, 0}},
                           {"mass", 0.2}}};
      },
      "field 'collision[0].quat': must be a unit quaternion");
  std::ofstream(dir / "broken.json") << "{\"name\": ";
  EXPECT_THAT([&] { LoadToolModel(dir / "broken.json"); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("broken.json"), HasSubstr("not valid JSON"))));
}

TEST(ToolModelTest, SaveLoadRoundTrip) {
  ToolModel tool = LoadToolModel(MeshData("sidecars/user_cube.json"));
  tool.name = "cube_tool";
  tool.family = "stick";
  CollisionPart box;
  box.type = CollisionPart::Type::kBox;
  box.size = Eigen::Vector3d(0.05, 0.05, 0.03);
  box.X_TP.translate(Eigen::Vector3d(0.05, 0.05, 0.03));
  box.X_TP.rotate(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  box.mass = 0.15;
  CollisionPart cylinder;
  cylinder.type = CollisionPart::Type::kCylinder;
  cylinder.size = Eigen::Vector3d(0.02, 0.04, 0.0);
  cylinder.X_TP.translate(Eigen::Vector3d(0.05, 0.05, 0.07));
  cylinder.mass = 0.05;
  tool.collision = {box, cylinder};
  const auto dir = FreshTempDir();
  SaveToolModel(tool, dir);
  ASSERT_TRUE(std::filesystem::exists(dir / "cube_tool.stl"));
  const ToolModel loaded = LoadToolModel(dir / "cube_tool.json");
  EXPECT_EQ(loaded.name, tool.name);
  EXPECT_EQ(loaded.family, tool.family);
  EXPECT_EQ(loaded.mass, tool.mass);
  EXPECT_EQ(loaded.mesh_file, dir / "cube_tool.stl");
  EXPECT_EQ(loaded.mesh.vertices, tool.mesh.vertices);  // already float-exact
  EXPECT_EQ(loaded.mesh.faces, tool.mesh.faces);
  EXPECT_TRUE(loaded.handle.center.isApprox(tool.handle.center, kTol));
  EXPECT_TRUE(loaded.effector.axis.isApprox(tool.effector.axis, kTol));
  EXPECT_EQ(loaded.effector.radius, tool.effector.radius);
  EXPECT_EQ(loaded.symmetries, tool.symmetries);
  EXPECT_EQ(loaded.params, tool.params);
  EXPECT_NEAR(loaded.total_length, tool.total_length, kTol);
  ASSERT_EQ(loaded.collision.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(loaded.collision[i].type, tool.collision[i].type);
    EXPECT_TRUE(loaded.collision[i].size.isApprox(tool.collision[i].size, kTol));
    EXPECT_TRUE(loaded.collision[i].X_TP.isApprox(tool.collision[i].X_TP, kTol));
    EXPECT_EQ(loaded.collision[i].mass, tool.collision[i].mass);
  }
}

TEST(ToolLibraryTest, LoadsFolderSortedByNameAndNamesBadFiles) {
  const auto dir = FreshTempDir();
  WriteVariant(dir, "b_tool", [](nlohmann::json&) {});
  WriteVariant(dir, "a_tool", [](nlohmann::json&) {});
  std::ofstream(dir / "notes.txt") << "not a sidecar";
  const auto tools = LoadToolLibrary(dir);
  ASSERT_EQ(tools.size(), 2u);
  EXPECT_EQ(tools[0].name, "a_tool");
  EXPECT_EQ(tools[1].name, "b_tool");

  WriteVariant(dir, "c_tool", [](nlohmann::json& j) { j.erase("handle"); });
  EXPECT_THAT([&] { LoadToolLibrary(dir); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("c_tool.json"), HasSubstr("field 'handle': missing"))));
  std::filesystem::remove(dir / "c_tool.json");
  WriteVariant(dir, "d_tool", [](nlohmann::json& j) { j["name"] = "a_tool"; });
  EXPECT_THAT([&] { LoadToolLibrary(dir); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("is used by another sidecar")));
  EXPECT_THAT([&] { LoadToolLibrary(dir / "nowhere"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("is not a folder")));
}

}  // namespace
}  // namespace toolbench::toollib
