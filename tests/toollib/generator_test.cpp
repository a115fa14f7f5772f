#include "toollib/generator.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <set>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/paths.h"
#include "tests/toollib/test_util.h"
#include "toollib/mesh.h"
#include "toollib/tool_model.h"

namespace toolbench::toollib {
namespace {

using testing::FreshTempDir;

constexpr double kMassTol = 1e-9;        // relative
constexpr double kJsonTol = 1e-9;        // numbers in sidecars
constexpr double kBoxInflation = 0.002;  // collision parts may exceed the mesh box by this [m]
constexpr double kInset = 0.001;         // probe points this far inside each collision part [m]

// Generating takes about half a second; do it once per process.
class GeneratorTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { tools_ = new std::vector<ToolModel>(GenerateToolLibrary()); }
  static void TearDownTestSuite() {
    delete tools_;
    tools_ = nullptr;
  }
  static const std::vector<ToolModel>& tools() { return *tools_; }

 private:
  static std::vector<ToolModel>* tools_;
};

std::vector<ToolModel>* GeneratorTest::tools_ = nullptr;

// Generalised winding number of the closed mesh around p: 1 inside, 0 outside.
double WindingNumber(const TriangleMesh& mesh, const Eigen::Vector3d& p) {
  double total = 0.0;
  for (Eigen::Index f = 0; f < mesh.faces.cols(); ++f) {
    const Eigen::Vector3d a = mesh.vertices.col(mesh.faces(0, f)) - p;
    const Eigen::Vector3d b = mesh.vertices.col(mesh.faces(1, f)) - p;
    const Eigen::Vector3d c = mesh.vertices.col(mesh.faces(2, f)) - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double numerator = a.dot(b.cross(c));
    const double denominator = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    total += 2.0 * std::atan2(numerator, denominator);
  }
  return total / (4.0 * std::numbers::pi);
}

// Points just inside a collision part (corners, rims, centre), in the tool frame.
std::vector<Eigen::Vector3d> ProbePoints(const CollisionPart& part) {
  std::vector<Eigen::Vector3d> points_P;
  const Eigen::Vector3d& s = part.size;
  switch (part.type) {
    case CollisionPart::Type::kBox: {
      const Eigen::Vector3d inner = (s.array() - (0.4 * s.array()).min(kInset)).matrix();
      for (int i = 0; i < 8; ++i) {
        points_P.emplace_back((i & 1) ? inner.x() : -inner.x(), (i & 2) ? inner.y() : -inner.y(),
                              (i & 4) ? inner.z() : -inner.z());
      }
      break;
    }
    case CollisionPart::Type::kCylinder: {
      const double r = s.x() - std::min(kInset, 0.4 * s.x());
      const double h = s.y() - std::min(kInset, 0.4 * s.y());
      for (int k = 0; k < 12; ++k) {
        const double angle = 2.0 * std::numbers::pi * k / 12;
        points_P.emplace_back(r * std::cos(angle), r * std::sin(angle), h);
        points_P.emplace_back(r * std::cos(angle), r * std::sin(angle), -h);
      }
      break;
    }
    case CollisionPart::Type::kSphere: {
      const double r = s.x() - std::min(kInset, 0.4 * s.x());
      for (int d = 0; d < 3; ++d) {
        points_P.push_back(r * Eigen::Vector3d::Unit(d));
        points_P.push_back(-r * Eigen::Vector3d::Unit(d));
      }
      break;
    }
    default:
      ADD_FAILURE() << "unexpected collision type " << CollisionTypeName(part.type);
  }
  points_P.push_back(Eigen::Vector3d::Zero());
  std::vector<Eigen::Vector3d> points_T;
  for (const Eigen::Vector3d& p_P : points_P) {
    points_T.push_back(part.X_TP * p_P);
  }
  return points_T;
}

bool PartContains(const CollisionPart& part, const Eigen::Vector3d& p_T) {
  constexpr double kEps = 1e-9;
  const Eigen::Vector3d p = part.X_TP.inverse() * p_T;
  switch (part.type) {
    case CollisionPart::Type::kBox:
      return (p.cwiseAbs() - part.size).maxCoeff() <= kEps;
    case CollisionPart::Type::kCylinder:
      return p.head<2>().norm() <= part.size.x() + kEps && std::abs(p.z()) <= part.size.y() + kEps;
    case CollisionPart::Type::kSphere:
      return p.norm() <= part.size.x() + kEps;
    default:
      return false;
  }
}

// Axis-aligned box of a part in the tool frame.
Eigen::AlignedBox3d PartBounds(const CollisionPart& part) {
  Eigen::AlignedBox3d box;
  const Eigen::Matrix3d R = part.X_TP.linear();
  const Eigen::Vector3d c = part.X_TP.translation();
  Eigen::Vector3d half;
  for (int i = 0; i < 3; ++i) {
    switch (part.type) {
      case CollisionPart::Type::kBox:
        half[i] = R.row(i).cwiseAbs().dot(part.size);
        break;
      case CollisionPart::Type::kCylinder: {
        const double a = std::abs(R(i, 2));
        half[i] = part.size.y() * a + part.size.x() * std::sqrt(std::max(0.0, 1.0 - a * a));
        break;
      }
      default:
        half[i] = part.size.x();
    }
  }
  box.extend(c - half);
  box.extend(c + half);
  return box;
}

TEST_F(GeneratorTest, EightFamiliesOfFourNamedVariants) {
  ASSERT_GE(tools().size(), 30u);
  std::map<std::string, int> per_family;
  std::set<std::string> names;
  for (const ToolModel& tool : tools()) {
    ++per_family[tool.family];
    EXPECT_TRUE(names.insert(tool.name).second) << tool.name;
    EXPECT_EQ(tool.name, tool.family + "_" + std::to_string(per_family[tool.family]));
    EXPECT_EQ(tool.mesh_file, tool.name + ".stl");
  }
  EXPECT_EQ(per_family.size(), 8u);
  for (const auto family : kToolFamilies) {
    EXPECT_EQ(per_family[std::string(family)], 4) << family;
  }
}

TEST_F(GeneratorTest, MeshesAreSingleValidShells) {
  for (const ToolModel& tool : tools()) {
    SCOPED_TRACE(tool.name);
    const MeshReport report = ValidateMesh(tool.mesh);
    EXPECT_TRUE(report.valid) << (report.problems.empty() ? "" : report.problems.front());
    EXPECT_EQ(report.num_components, 1);
    EXPECT_FALSE(HasSelfIntersections(tool.mesh));
    EXPECT_GE(report.num_faces, 1500);
    EXPECT_LE(report.num_faces, 5500);
    // Vertices are float-exact, so a binary STL stores them losslessly.
    EXPECT_EQ(tool.mesh.vertices, tool.mesh.vertices.cast<float>().cast<double>().eval());
  }
}

TEST_F(GeneratorTest, RealisticSizesAndMasses) {
  for (const ToolModel& tool : tools()) {
    SCOPED_TRACE(tool.name);
    const Eigen::AlignedBox3d box = Bounds(tool.mesh);
    EXPECT_NEAR(box.min().z(), 0.0, 1e-6);  // butt end at the origin
    EXPECT_NEAR(tool.total_length, box.max().z() - box.min().z(), 1e-12);
    EXPECT_GE(tool.total_length, 0.25);
    EXPECT_LE(tool.total_length, 0.60);
    EXPECT_GE(2.0 * tool.handle.radius, 0.020);
    EXPECT_LE(2.0 * tool.handle.radius, 0.035);
    EXPECT_GE(tool.mass, 0.08);
    EXPECT_LE(tool.mass, 0.6);
    EXPECT_NEAR(tool.mass, tool.params.at("density") * Volume(tool.mesh), kMassTol * tool.mass);
    EXPECT_TRUE(tool.handle.axis.isApprox(Eigen::Vector3d::UnitZ()));
    EXPECT_NEAR(tool.effector.axis.norm(), 1.0, 1e-12);
    // The grasp (80 mm long) fits on the handle; its centre is at or below mid-tool.
    EXPECT_GE(tool.handle.length, 0.08);
    EXPECT_LE(tool.handle.center.z(), 0.5 * tool.total_length);
    // The effector lies beyond the handle's grasp region, toward +z.
    EXPECT_GT(tool.effector.center.z(), tool.handle.center.z());
    if (tool.family != "stick") {
      EXPECT_GE(tool.effector.center.x(), 0.0);  // works toward +x
    }
  }
}

TEST_F(GeneratorTest, CollisionPartsSplitTheMassAndStayInsideTheShape) {
  for (const ToolModel& tool : tools()) {
    SCOPED_TRACE(tool.name);
    ASSERT_FALSE(tool.collision.empty());
    double mass = 0.0;
    Eigen::AlignedBox3d inflated = Bounds(tool.mesh);
    inflated.min().array() -= kBoxInflation;
    inflated.max().array() += kBoxInflation;
    for (const CollisionPart& part : tool.collision) {
      EXPECT_GT(part.mass, 0.0);
      mass += part.mass;
      EXPECT_NE(part.type,
                CollisionPart::Type::kMesh);  // primitives only: a hull would fill the hoe
      EXPECT_TRUE(inflated.contains(PartBounds(part))) << CollisionTypeName(part.type);
      for (const Eigen::Vector3d& p : ProbePoints(part)) {
        EXPECT_NEAR(WindingNumber(tool.mesh, p), 1.0, 1e-3)
            << CollisionTypeName(part.type) << " probe " << p.transpose() << " is outside the mesh";
      }
    }
    EXPECT_NEAR(mass, tool.mass, kMassTol * tool.mass);
  }
}

TEST_F(GeneratorTest, CollisionPartsCoverHandleAndEffectorCentres) {
  for (const ToolModel& tool : tools()) {
    SCOPED_TRACE(tool.name);
    for (const Segment* segment : {&tool.handle, &tool.effector}) {
      bool covered = false;
      for (const CollisionPart& part : tool.collision) {
        covered = covered || PartContains(part, segment->center);
      }
      EXPECT_TRUE(covered) << "segment centre " << segment->center.transpose();
      EXPECT_NEAR(WindingNumber(tool.mesh, segment->center), 1.0, 1e-3);
    }
  }
}

// Numbers equal within kJsonTol, everything else exactly.
void ExpectJsonNear(const nlohmann::json& a, const nlohmann::json& b, const std::string& path) {
  if (a.is_number() && b.is_number()) {
    EXPECT_NEAR(a.get<double>(), b.get<double>(), kJsonTol) << path;
    return;
  }
  ASSERT_EQ(a.type(), b.type()) << path;
  if (a.is_object()) {
    ASSERT_EQ(a.size(), b.size()) << path;
    for (const auto& [key, value] : a.items()) {
      ASSERT_TRUE(b.contains(key)) << path << "." << key;
      ExpectJsonNear(value, b.at(key), path + "." + key);
    }
  } else if (a.is_array()) {
    ASSERT_EQ(a.size(), b.size()) << path;
    for (std::size_t i = 0; i < a.size(); ++i) {
      ExpectJsonNear(a[i], b[i], path + "[" + std::to_string(i) + "]");
    }
  } else {
    EXPECT_EQ(a, b) << path;
  }
}

// The committed assets/tools must be exactly what the generator makes today: regenerate with
// `toolbench_toolgen assets/tools` after changing the generator.
TEST_F(GeneratorTest, CommittedAssetsMatchTheGenerator) {
  const std::filesystem::path assets = AssetsDir() / "tools";
  const auto fresh = FreshTempDir();
  std::set<std::string> generated;
  for (const ToolModel& tool : tools()) {
    SCOPED_TRACE(tool.name);
    generated.insert(tool.name);
    SaveToolModel(tool, fresh);
    const auto committed_json = assets / (tool.name + ".json");
    ASSERT_TRUE(std::filesystem::exists(committed_json)) << committed_json;
    ExpectJsonNear(nlohmann::json::parse(ReadTextFile(fresh / (tool.name + ".json"))),
                   nlohmann::json::parse(ReadTextFile(committed_json)), tool.name);
    const TriangleMesh committed = ReadMesh(assets / (tool.name + ".stl"));
    EXPECT_EQ(committed.vertices.cols(), tool.mesh.vertices.cols());
    EXPECT_EQ(committed.faces.cols(), tool.mesh.faces.cols());
    EXPECT_NEAR(Volume(committed), Volume(tool.mesh), 1e-9 * Volume(tool.mesh));
  }
  for (const auto& entry : std::filesystem::directory_iterator(assets)) {
    if (entry.path().extension() == ".json") {
      EXPECT_TRUE(generated.count(entry.path().stem().string()))
          << entry.path() << " is not made by the generator";
    }
  }
}

// Where a hand can hold each tool like its handle (HandleBarSpan): the whole stick, a shovel's or
// spatula's handle and neck up to its blade, a hook's or hammer's handle alone (to the slice).
TEST_F(GeneratorTest, HandleBarSpanRunsAlongTheBarOfEachTool) {
  constexpr double kSlice = 0.005;
  int sticks = 0, necks = 0;
  for (const ToolModel& tool : tools()) {
    SCOPED_TRACE(tool.name);
    const AxisSpan span = HandleBarSpan(tool.mesh, tool.handle, kSlice);
    const double half = tool.handle.length / 2;
    const double butt = -tool.handle.center.dot(tool.handle.axis);  // the tool's end at z_T = 0
    EXPECT_NEAR(span.min_m, std::max(-half, butt), 1e-9);           // library handles end at the butt
    // An L-stick's foot slants back over its handle's declared end (lstick_4: from 3.5 cm inside).
    if (tool.family != "lstick") {
      EXPECT_GE(span.max_m, half - kSlice);
    }
    const double effector_start =
        (tool.effector.center - tool.handle.center).dot(tool.handle.axis) - tool.effector.length / 2;
    if (tool.family == "stick") {
      ++sticks;
      EXPECT_NEAR(span.max_m, tool.total_length + butt, 1e-9);  // to the other end
    } else if (tool.family == "shovel") {
      ++necks;
      EXPECT_GT(span.max_m, half + 0.005);             // the neck
      EXPECT_LE(span.max_m, effector_start + kSlice);  // not the blade
    } else if (tool.family == "hook" || tool.family == "hammer") {
      EXPECT_LE(span.max_m, half + 0.006);  // not the thin shaft, not the head
    }
  }
  EXPECT_EQ(sticks, 4);
  EXPECT_EQ(necks, 4);

  // A handle declared much thicker than the tool: no slice there is a bar like it.
  ToolModel thin = tools().front();
  thin.handle.radius = 0.1;
  const AxisSpan none = HandleBarSpan(thin.mesh, thin.handle);
  EXPECT_EQ(none.min_m, 0.0);
  EXPECT_EQ(none.max_m, 0.0);
  EXPECT_THAT([&] { HandleBarSpan(thin.mesh, thin.handle, 0.0); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("slice_m")));
  thin.handle.axis.setZero();
  EXPECT_THAT([&] { HandleBarSpan(thin.mesh, thin.handle); },
              ::testing::ThrowsMessage<std::invalid_argument>(::testing::HasSubstr("handle axis")));
}

TEST_F(GeneratorTest, SaveLoadRoundTripIsExact) {
  const auto dir = FreshTempDir();
  for (const ToolModel& tool : tools()) {
    SaveToolModel(tool, dir);
  }
  const std::vector<ToolModel> loaded = LoadToolLibrary(dir);
  ASSERT_EQ(loaded.size(), tools().size());
  std::map<std::string, const ToolModel*> by_name;
  for (const ToolModel& tool : tools()) {
    by_name[tool.name] = &tool;
  }
  for (const ToolModel& back : loaded) {
    SCOPED_TRACE(back.name);
    const ToolModel& tool = *by_name.at(back.name);
    EXPECT_EQ(back.family, tool.family);
    EXPECT_EQ(back.mass, tool.mass);
    EXPECT_EQ(back.mesh.vertices, tool.mesh.vertices);
    EXPECT_EQ(back.mesh.faces, tool.mesh.faces);
    EXPECT_EQ(back.mesh_file, dir / (tool.name + ".stl"));
    EXPECT_EQ(back.params, tool.params);
    EXPECT_EQ(back.symmetries, tool.symmetries);
    EXPECT_EQ(back.handle.center, tool.handle.center);
    EXPECT_TRUE(back.effector.axis.isApprox(tool.effector.axis, 1e-12));
    ASSERT_EQ(back.collision.size(), tool.collision.size());
    for (std::size_t i = 0; i < tool.collision.size(); ++i) {
      EXPECT_EQ(back.collision[i].type, tool.collision[i].type);
      EXPECT_EQ(back.collision[i].size, tool.collision[i].size);
      EXPECT_TRUE(back.collision[i].X_TP.isApprox(tool.collision[i].X_TP, 1e-12));
      EXPECT_EQ(back.collision[i].mass, tool.collision[i].mass);
    }
  }
}

TEST(WriteToolLibraryTest, WritesALoadableLibrary) {
  const auto dir = FreshTempDir();
  WriteToolLibrary(dir);
  int meshes = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    meshes += entry.path().extension() == ".stl" ? 1 : 0;
  }
  const std::vector<ToolModel> tools = LoadToolLibrary(dir);
  EXPECT_EQ(meshes, static_cast<int>(tools.size()));
  EXPECT_GE(tools.size(), 30u);
}

}  // namespace
}  // namespace toolbench::toollib
