// Shape analysis of every library tool (slow: AFSR + SDF + superquadrics, ~1-3 s per tool).
// With TOOLBENCH_SHAPE_DEBUG_DIR set, writes <tool>_parts.ply and a <tool>_parts.png view
// (orthographic, x_T right, z_T up) per tool there.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/paths.h"
#include "perception/parts.h"
#include "toollib/tool_model.h"

namespace toolbench::perception {
namespace {

constexpr double kCenterTol = 0.02;                  // handle centre vs sidecar [m]
const double kAxisTolCos = std::cos(15.0 * M_PI / 180);  // handle axis vs +z_T

const std::vector<toollib::ToolModel>& Library() {
  static const std::vector<toollib::ToolModel> library = toollib::LoadToolLibrary(AssetsDir() / "tools");
  return library;
}

void WriteDebug(const std::filesystem::path& dir, const ModelShape& shape) {
  std::filesystem::create_directories(dir);
  WritePartsPly(dir / (shape.model + "_parts.ply"), shape.parts, shape.handle.part, 2000);
  constexpr int kPx = 600;
  constexpr double kScale = 1300.0;  // px per metre
  cv::Mat image(kPx, kPx / 2 + 100, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Scalar palette[] = {{40, 80, 230}, {75, 180, 60}, {40, 200, 240}, {200, 60, 170}, {200, 130, 240}};
  for (std::size_t i = 0; i < shape.parts.size(); ++i) {
    const cv::Scalar c = static_cast<int>(i) == shape.handle.part ? cv::Scalar(230, 90, 40) : palette[i % 5];
    for (Eigen::Index k = 0; k < shape.parts[i].points.cols(); ++k) {
      const Eigen::Vector3f p = shape.parts[i].points.col(k);
      cv::circle(image, {static_cast<int>(image.cols / 2 + kScale * p.x()), static_cast<int>(kPx - 20 - kScale * p.z())},
                 1, c, cv::FILLED);
    }
  }
  const Eigen::Vector3d a = shape.handle.center, b = shape.handle.center + 0.05 * shape.handle.axis;
  cv::arrowedLine(image, {static_cast<int>(image.cols / 2 + kScale * a.x()), static_cast<int>(kPx - 20 - kScale * a.z())},
                  {static_cast<int>(image.cols / 2 + kScale * b.x()), static_cast<int>(kPx - 20 - kScale * b.z())},
                  {0, 0, 0}, 2);
  cv::putText(image, shape.model, {5, 20}, cv::FONT_HERSHEY_SIMPLEX, 0.6, {0, 0, 0}, 1);
  cv::imwrite((dir / (shape.model + "_parts.png")).string(), image);
}

const ShapeSegmentations& Recorded() {
  static const ShapeSegmentations recorded = ReadShapeSegmentations(AssetsDir() / "models" / "library_segmentation.json");
  return recorded;
}

// Every library tool's shipped segmentation matches its mesh and the default options (else the
// file is stale: remake it as assets/models/README.md says), and the analysis from it finds the
// handle the sidecar declares. This is the analysis every episode uses.
TEST(ShapeLibraryTest, HandleIsTheSidecarHandleForEveryTool) {
  const char* debug_dir = std::getenv("TOOLBENCH_SHAPE_DEBUG_DIR");
  ASSERT_FALSE(Library().empty());
  int correct = 0;
  for (const toollib::ToolModel& model : Library()) {
    const auto recorded = Recorded().find(ShapeCacheKey(model, {}));
    ASSERT_NE(recorded, Recorded().end())
        << model.name << " has no segmentation for its mesh and the default options in "
        << "assets/models/library_segmentation.json: run build/toolbench tools --write-segmentations "
        << "assets/models/library_segmentation.json";
    const auto start = std::chrono::steady_clock::now();
    const ModelShape shape = AnalyzeModelShape(model, {}, recorded->second);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (debug_dir != nullptr) WriteDebug(debug_dir, shape);
    std::printf("%-10s status %d parts %zu faces %5d fallback %d handle %d: centre err %5.1f mm, axis.z %.3f, "
                "r %4.1f mm, L %5.1f mm, protrusion %5.1f mm | %.2f s\n",
                model.name.c_str(), static_cast<int>(shape.status), shape.parts.size(), shape.mesh_faces,
                shape.mesh_fallback, shape.handle.part, 1000 * (shape.handle.center - model.handle.center).norm(),
                shape.handle.axis.z(), 1000 * shape.handle.radius, 1000 * shape.handle.length,
                1000 * shape.features.effector_protrusion, seconds);
    EXPECT_EQ(shape.status, ShapeStatus::kOk) << model.name << ": " << shape.reason;
    const bool ok = shape.handle.part >= 0 && (shape.handle.center - model.handle.center).norm() < kCenterTol &&
                    shape.handle.axis.z() > kAxisTolCos;
    EXPECT_TRUE(ok) << model.name;
    EXPECT_GE(shape.parts.size(), 1u) << model.name;
    EXPECT_LE(shape.parts.size(), 6u) << model.name;
    EXPECT_NEAR(shape.features.total_length, model.total_length, 0.01) << model.name;
    correct += ok ? 1 : 0;
  }
  std::printf("handle correct for %d of %zu tools\n", correct, Library().size());
}

const toollib::ToolModel& Tool(const std::string& name) {
  for (const toollib::ToolModel& m : Library()) {
    if (m.name == name) return m;
  }
  throw std::runtime_error("no tool " + name);
}

void ExpectSameShape(const ModelShape& a, const ModelShape& b) {
  ASSERT_EQ(a.parts.size(), b.parts.size());
  for (std::size_t i = 0; i < a.parts.size(); ++i) {
    EXPECT_EQ(a.parts[i].points, b.parts[i].points);
    EXPECT_EQ(a.parts[i].sq.size, b.parts[i].sq.size);
    EXPECT_EQ(a.parts[i].sq.pose.matrix(), b.parts[i].sq.pose.matrix());
    EXPECT_EQ(a.parts[i].cylinder_score, b.parts[i].cylinder_score);
  }
  EXPECT_EQ(a.handle.part, b.handle.part);
  EXPECT_EQ(a.handle.center, b.handle.center);
  EXPECT_EQ(a.handle.X_FH.matrix(), b.handle.X_FH.matrix());
  EXPECT_EQ(a.features.effector_center, b.features.effector_center);
  EXPECT_EQ(a.features.effector_protrusion, b.features.effector_protrusion);
}

TEST(ShapeCacheTest, HitsReturnIdenticalDataAndChangedOptionsMiss) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "toolbench_shape_cache_test";
  std::filesystem::remove_all(dir);
  const toollib::ToolModel& hoe = Tool("hoe_1");
  ShapeOptions options;
  ShapeCache cache(dir);
  const ModelShape first = cache.Get(hoe, options);
  EXPECT_EQ(cache.misses(), 1);
  const ModelShape& second = cache.Get(hoe, options);
  EXPECT_EQ(cache.memory_hits(), 1);
  ExpectSameShape(first, second);
  // Same model and options, computed again: CGAL's AFSR breaks ties between equally plausible
  // border edges by pointer address (std::set<pair<criteria, IO_edge_type*>>), so the mesh can
  // differ by a few faces between runs; the handle must not move.
  const ModelShape again = AnalyzeModelShape(hoe, options);
  EXPECT_LT((again.handle.center - first.handle.center).norm(), 0.002);
  EXPECT_GT(again.handle.axis.dot(first.handle.axis), std::cos(2.0 * M_PI / 180));

  // A new process (a fresh cache on the same folder) reads the file: identical data.
  ShapeCache fresh(dir);
  const ModelShape& from_disk = fresh.Get(hoe, options);
  EXPECT_EQ(fresh.disk_hits(), 1);
  EXPECT_EQ(fresh.misses(), 0);
  ExpectSameShape(first, from_disk);

  // A changed option, or a changed mesh, is a different key: a miss, never stale data.
  options.sdf_smoothing = 0.3;
  EXPECT_NE(ShapeCacheKey(hoe, options), ShapeCacheKey(hoe, ShapeOptions{}));
  fresh.Get(hoe, options);
  EXPECT_EQ(fresh.misses(), 1);
  toollib::ToolModel moved = hoe;
  moved.mesh.vertices(0, 0) += 1e-4;
  EXPECT_NE(ShapeCacheKey(moved, ShapeOptions{}), ShapeCacheKey(hoe, ShapeOptions{}));
  std::filesystem::remove_all(dir);
}

// The analysis splits into the segmentation (which a process cannot repeat exactly) and the rest,
// a function of the labels: the same labels give the same analysis, bit for bit, and a freshly
// segmented analysis finds the same handle within the reconstruction's variation.
TEST(ShapeSegmentationTest, SameLabelsGiveTheSameAnalysis) {
  const toollib::ToolModel& hoe = Tool("hoe_1");
  const ShapeSegmentation seg = SegmentModelShape(hoe, {});
  ASSERT_EQ(seg.status, ShapeStatus::kOk) << seg.reason;
  ASSERT_EQ(seg.labels.size(), 4000u);
  const ModelShape a = AnalyzeModelShape(hoe, {}, seg);
  const ModelShape b = AnalyzeModelShape(hoe, {}, seg);
  ExpectSameShape(a, b);
  const ModelShape recorded = AnalyzeModelShape(hoe, {}, Recorded().at(ShapeCacheKey(hoe, {})));
  EXPECT_LT((recorded.handle.center - a.handle.center).norm(), 0.002);
  EXPECT_GT(recorded.handle.axis.dot(a.handle.axis), std::cos(2.0 * M_PI / 180));

  // Labels that do not fit the samples are refused, naming the model.
  ShapeSegmentation short_seg = seg;
  short_seg.labels.pop_back();
  EXPECT_THROW(
      {
        try {
          AnalyzeModelShape(hoe, {}, short_seg);
        } catch (const std::invalid_argument& e) {
          EXPECT_NE(std::string(e.what()).find("hoe_1"), std::string::npos) << e.what();
          throw;
        }
      },
      std::invalid_argument);
  ShapeSegmentation out_of_range = seg;
  out_of_range.labels[7] = seg.num_labels;
  EXPECT_THROW(AnalyzeModelShape(hoe, {}, out_of_range), std::invalid_argument);
  // A failed segmentation is a result with its reason.
  ShapeSegmentation failed;
  failed.status = ShapeStatus::kSegmentationFailed;
  failed.reason = "no surface";
  const ModelShape none = AnalyzeModelShape(hoe, {}, failed);
  EXPECT_EQ(none.status, ShapeStatus::kSegmentationFailed);
  EXPECT_EQ(none.reason, "no surface");
}

// A cache given the recorded segmentations analyses a model from its record (not anew), under a
// key of its own on disk, and a second process reads that file.
TEST(ShapeSegmentationTest, CacheAnalysesFromTheRecord) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "toolbench_shape_seg_cache_test";
  std::filesystem::remove_all(dir);
  const toollib::ToolModel& hoe = Tool("hoe_1");
  ShapeCache cache(dir, Recorded());
  const ModelShape first = cache.Get(hoe, {});
  EXPECT_EQ(cache.misses(), 1);
  EXPECT_EQ(cache.recorded(), 1);
  ExpectSameShape(first, AnalyzeModelShape(hoe, {}, Recorded().at(ShapeCacheKey(hoe, {}))));
  EXPECT_TRUE(std::filesystem::exists(dir / (ShapeCacheKey(hoe, {}) + "-seg.json")));
  ShapeCache again(dir, Recorded());
  ExpectSameShape(first, again.Get(hoe, {}));
  EXPECT_EQ(again.disk_hits(), 1);
  // Without the record, the same folder does not answer with the recorded analysis.
  ShapeCache unrecorded(dir);
  unrecorded.Get(hoe, {});
  EXPECT_EQ(unrecorded.misses(), 1);
  EXPECT_EQ(unrecorded.recorded(), 0);
  std::filesystem::remove_all(dir);
}

TEST(ShapeSegmentationTest, FileRoundTripsAndBadFilesAreNamed) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "toolbench_shape_seg_file_test";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  ShapeSegmentations written;
  ShapeSegmentation seg;
  seg.status = ShapeStatus::kOk;
  seg.num_labels = 12;
  seg.labels = {0, 11, 3, 3, 10};
  seg.mesh_faces = 77;
  seg.mesh_fallback = true;
  written["tool-a"] = seg;
  WriteShapeSegmentations(dir / "s.json", written);
  const ShapeSegmentations read = ReadShapeSegmentations(dir / "s.json");
  ASSERT_EQ(read.size(), 1u);
  EXPECT_EQ(read.at("tool-a").labels, seg.labels);
  EXPECT_EQ(read.at("tool-a").num_labels, 12);
  EXPECT_EQ(read.at("tool-a").mesh_faces, 77);
  EXPECT_TRUE(read.at("tool-a").mesh_fallback);
  EXPECT_EQ(read.at("tool-a").status, ShapeStatus::kOk);

  auto expect_named = [&](const std::string& text, const std::string& what) {
    const std::filesystem::path file = dir / "bad.json";
    std::ofstream(file) << text;
    try {
      ReadShapeSegmentations(file);
      ADD_FAILURE() << "no error for " << text;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("bad.json"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  expect_named("{\"format\": 1, \"segm", "not valid JSON");
  expect_named(R"({"format": 2, "segmentations": {}})", "format");
  expect_named(R"({"format": 1, "segmentations": {"t": {"num_labels": 2, "mesh_faces": 1, "mesh_fallback": false}}})",
               "missing");
  expect_named(R"({"format": 1, "segmentations": {"t": {"num_labels": 2, "mesh_faces": 1, "mesh_fallback": false,
                 "labels": "0120"}}})",
               "label '2'");
  EXPECT_THROW(ReadShapeSegmentations(dir / "missing.json"), std::runtime_error);
  seg.status = ShapeStatus::kSegmentationFailed;
  EXPECT_THROW(WriteShapeSegmentations(dir / "t.json", {{"tool-b", seg}}), std::invalid_argument);
  std::filesystem::remove_all(dir);
}

TEST(ObservedShapeTest, FindsTheHandleOfAOneSidedView) {
  // Camera-facing samples of hoe_1 placed in R, as a depth camera 0.6 m in front would see them.
  const toollib::ToolModel& hoe = Tool("hoe_1");
  const SurfaceSamples all = SampleSurface(hoe.mesh, 8000, 3);
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();
  X_RT.linear() = Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitX()).toRotationMatrix();
  X_RT.translation() = Eigen::Vector3d(0.3, 0.2, -0.1);
  const Eigen::Vector3d camera_T(0.0, -0.6, 0.15);
  std::vector<int> visible;
  for (Eigen::Index i = 0; i < all.points.cols(); ++i) {
    if (all.normals.col(i).cast<double>().dot(camera_T - all.points.col(i).cast<double>()) > 0) visible.push_back(static_cast<int>(i));
  }
  Eigen::Matrix3Xf p_R(3, static_cast<Eigen::Index>(visible.size()));
  for (std::size_t i = 0; i < visible.size(); ++i) {
    p_R.col(static_cast<Eigen::Index>(i)) = (X_RT * all.points.col(visible[i]).cast<double>()).cast<float>();
  }
  ShapeOptions options;
  options.radius_log_tolerance = 0.6;  // one-sided fits under-estimate radii
  const ModelShape shape = AnalyzeObservedShape(p_R, X_RT * camera_T, options);
  std::printf("observed hoe_1: status %d (%s) parts %zu handle %d centre err %.1f mm axis.z_T %.3f\n",
              static_cast<int>(shape.status), shape.reason.c_str(), shape.parts.size(), shape.handle.part,
              1000 * (shape.handle.center - X_RT * hoe.handle.center).norm(),
              (X_RT.linear().transpose() * shape.handle.axis).z());
  ASSERT_EQ(shape.status, ShapeStatus::kOk) << shape.reason;
  EXPECT_LT((shape.handle.center - X_RT * hoe.handle.center).norm(), 0.03);
  EXPECT_GT((X_RT.linear().transpose() * shape.handle.axis).z(), kAxisTolCos);
}

}  // namespace
}  // namespace toolbench::perception
