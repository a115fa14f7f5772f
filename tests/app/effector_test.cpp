// EffectorOf: the points the pull plans with cover the tool's faces, not only their corners.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "app/scene_setup.h"
#include "common/paths.h"
#include "toollib/tool_model.h"

namespace toolbench::app {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

// The largest distance from a point of a face (a barycentric grid on each) to the nearest of
// `points` [m].
double WorstFaceGap(const toollib::TriangleMesh& mesh, const Eigen::Matrix3Xd& points) {
  constexpr int kGrid = 8;
  double worst = 0.0;
  for (Eigen::Index f = 0; f < mesh.faces.cols(); ++f) {
    const auto corner = [&](int k) { return Eigen::Vector3d(mesh.vertices.col(mesh.faces(k, f)).cast<double>()); };
    for (int i = 0; i <= kGrid; ++i) {
      for (int j = 0; i + j <= kGrid; ++j) {
        const Eigen::Vector3d p = (i * corner(0) + j * corner(1) + (kGrid - i - j) * corner(2)) / kGrid;
        worst = std::max(worst, std::sqrt((points.colwise() - p).colwise().squaredNorm().minCoeff()));
      }
    }
  }
  return worst;
}

// The library's meshes have edges of at most 2 cm: their vertices are the points, as before.
TEST(EffectorOf, KeepsTheLibrarysVerticesAsTheyAre) {
  for (const toollib::ToolModel& model : toollib::LoadToolLibrary(AssetsDir() / "tools")) {
    const control::ToolEffector e = EffectorOf(model);
    EXPECT_EQ(e.tool_points_T, model.mesh.vertices) << model.name;
    if (model.name == "spatula_4") {
      EXPECT_LT(WorstFaceGap(model.mesh, e.tool_points_T), 0.011);
    }
  }
}

// A user's tool of a few large faces (a blade from CAD, two triangles 10 x 6 cm) is empty between
// its corners, where the pull's start check would see no tool over the ball: its faces get grid
// points no further apart than the library's edges.
TEST(EffectorOf, FillsLargeFacesWithPoints) {
  toollib::ToolModel model = toollib::LoadToolModel(AssetsDir() / "tools" / "spatula_4.json");
  model.mesh.vertices.resize(3, 4);
  model.mesh.vertices << 0, 0.10, 0.10, 0,  //
      0, 0, 0.06, 0.06,                      //
      0.30, 0.30, 0.30, 0.30;
  model.mesh.faces.resize(3, 2);
  model.mesh.faces << 0, 0, 1, 2, 2, 3;
  model.effector.center = Eigen::Vector3d(0.05, 0.03, 0.30);
  EXPECT_GT(WorstFaceGap(model.mesh, model.mesh.vertices.cast<double>()), 0.05);
  const control::ToolEffector e = EffectorOf(model);
  EXPECT_LT(WorstFaceGap(model.mesh, e.tool_points_T), 0.015);
  // The effector region's points are the tool's points near the effector centre.
  const double region = model.effector.length / 2 + model.effector.radius;
  ASSERT_GT(e.points_T.cols(), 4);
  for (Eigen::Index i = 0; i < e.points_T.cols(); ++i) {
    EXPECT_LE((e.points_T.col(i) - e.center_T).norm(), region + 1e-9);
  }
  EXPECT_THAT([&] { EffectorOf(model, 0.0); }, ThrowsMessage<std::invalid_argument>(HasSubstr("max_edge_m")));
}

}  // namespace
}  // namespace toolbench::app
