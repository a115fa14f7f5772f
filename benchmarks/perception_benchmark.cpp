// Shape analysis costs (issue 3): superquadric fit, AFSR + SDF parts of one tool, the full
// per-model analysis and a cache hit; the model-to-cloud fit that recognition and the held-tool
// estimate run. Inputs are seeded and built outside the timed loops.
#include <cmath>

#include <benchmark/benchmark.h>

#include "common/paths.h"
#include "common/rng.h"
#include "perception/model_fit.h"
#include "perception/parts.h"
#include "perception/superquadric.h"
#include "toollib/tool_model.h"

namespace {

using namespace toolbench;

/// Area-uniform samples of a 32 mm x 80 mm closed cylinder (the iCub hand's handle) at an
/// oblique pose, with 0.5 mm noise.
Eigen::Matrix3Xf HandleCylinder(int n) {
  Rng rng(5);
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, 2, 0.5).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(0.3, -0.1, 0.2);
  constexpr double r = 0.016, h = 0.040;
  const double side = 2 * M_PI * r * 2 * h, cap = M_PI * r * r;
  Eigen::Matrix3Xf p(3, n);
  for (int i = 0; i < n; ++i) {
    const double u = UniformReal(rng, 0, side + 2 * cap), phi = UniformReal(rng, -M_PI, M_PI);
    Eigen::Vector3d q;
    if (u < side) {
      q = {r * std::cos(phi), r * std::sin(phi), UniformReal(rng, -h, h)};
    } else {
      const double rr = r * std::sqrt(UniformReal(rng, 0, 1));
      q = {rr * std::cos(phi), rr * std::sin(phi), u < side + cap ? h : -h};
    }
    const Eigen::Vector3d noise(StandardNormal(rng), StandardNormal(rng), StandardNormal(rng));
    p.col(i) = (X * q + 0.0005 * noise).cast<float>();
  }
  return p;
}

const toollib::ToolModel& Hoe() {
  static const toollib::ToolModel hoe = toollib::LoadToolModel(AssetsDir() / "tools" / "hoe_1.json");
  return hoe;
}

/// FitSuperquadric on a cylinder cloud subsampled to Arg(0) points (3 axis assignments).
void BM_PerceptionFitSuperquadric(benchmark::State& state) {
  const Eigen::Matrix3Xf cloud = HandleCylinder(2000);
  perception::SuperquadricOptions options;
  options.max_points = static_cast<int>(state.range(0));
  int iterations = 0;
  for (auto _ : state) {
    const perception::SuperquadricFit fit = perception::FitSuperquadric(cloud, options);
    iterations = fit.iterations;
    benchmark::DoNotOptimize(fit.cost);
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["ipopt_iterations"] = iterations;
}
BENCHMARK(BM_PerceptionFitSuperquadric)->Arg(50)->Arg(300)->Unit(benchmark::kMillisecond);

/// SegmentParts of hoe_1 (4000 samples: AFSR + SDF + merging + one superquadric per part).
void BM_PerceptionSegmentParts(benchmark::State& state) {
  const perception::ShapeOptions options;
  const perception::SurfaceSamples samples = perception::SampleSurface(Hoe().mesh, options.samples, 1);
  for (auto _ : state) {
    const perception::PartsResult parts = perception::SegmentParts(samples, options);
    benchmark::DoNotOptimize(parts.parts.size());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_PerceptionSegmentParts)->Unit(benchmark::kMillisecond)->Iterations(3);

/// AnalyzeModelShape of hoe_1: sampling, parts, handle, features.
void BM_PerceptionAnalyzeModelShape(benchmark::State& state) {
  for (auto _ : state) {
    const perception::ModelShape shape = perception::AnalyzeModelShape(Hoe(), {});
    benchmark::DoNotOptimize(shape.handle.center);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_PerceptionAnalyzeModelShape)->Unit(benchmark::kMillisecond)->Iterations(3);

/// ShapeCache::Get for a model already analysed (memory hit: the key hashes the mesh).
void BM_PerceptionShapeCacheHit(benchmark::State& state) {
  perception::ShapeCache cache;
  const perception::ShapeOptions options;
  cache.Get(Hoe(), options);
  for (auto _ : state) benchmark::DoNotOptimize(&cache.Get(Hoe(), options));
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_PerceptionShapeCacheHit)->Unit(benchmark::kMicrosecond);

/// A one-sided view of hoe_1 leaning on the rack 0.8 m from the camera: the camera-facing ones of
/// 6000 surface samples (not the fitter's own: another seed) with 1 mm isotropic noise.
Eigen::Matrix3Xf HoeView(const Eigen::Vector3d& p_R_camera) {
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();
  X_RT.linear() = (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(-1.2, Eigen::Vector3d::UnitX()))
                      .toRotationMatrix();
  X_RT.translation() = Eigen::Vector3d(-0.1, 0.5, -0.05);
  const perception::SurfaceSamples dense = perception::SampleSurface(Hoe().mesh, 6000, 11);
  Rng rng(12);
  Eigen::Matrix3Xf view(3, dense.points.cols());
  Eigen::Index kept = 0;
  for (Eigen::Index i = 0; i < dense.points.cols(); ++i) {
    const Eigen::Vector3d p = X_RT * dense.points.col(i).cast<double>();
    if ((X_RT.linear() * dense.normals.col(i).cast<double>()).dot(p_R_camera - p) <= 0) continue;
    const Eigen::Vector3d noise(StandardNormal(rng), StandardNormal(rng), StandardNormal(rng));
    view.col(kept++) = (p + 0.001 * noise).cast<float>();
  }
  return view.leftCols(kept);
}

/// ModelFitter on that view with the default options: Arg(0) = 0 the candidate search alone (our
/// ICP loop on the coarse cloud), 1 the whole Fit (search, then PCL's ICP on up to 2000 points and
/// the visible-surface rounds). No depth image: the view check is not timed here.
void BM_PerceptionModelFit(benchmark::State& state) {
  const Eigen::Vector3d camera(0.1, 0.0, 0.4);
  const Eigen::Matrix3Xf view = HoeView(camera);
  const perception::ModelFitter fitter(Hoe(), {});
  double fit_error = 0.0;
  for (auto _ : state) {
    const perception::ModelFitResult fit = state.range(0) == 0 ? fitter.Search(view, camera) : fitter.Fit(view, camera);
    fit_error = fit.fit_error;
    benchmark::DoNotOptimize(fit.X_RT);
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["observed_points"] = static_cast<double>(view.cols());
  state.counters["fit_error_mm"] = 1000.0 * fit_error;
}
BENCHMARK(BM_PerceptionModelFit)->ArgName("whole_fit")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace
