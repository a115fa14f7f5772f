// Planning cost of the pull (PlanPull): the orientation search screens ~1500 tool poses with a
// cheap IK before planning paths. Arg 0: screening Ipopt iterations after a failed pre-solve
// (10 = the default until session 5, 0 = none); arg 1: 0 = a ball the held rake can reach
// behind, 1 = one too far (the search fails: the case whose cost dominated the episodes); arg 2:
// 1 = the path solves run Ipopt after a failed pre-solve (as until session 5), 0 = they do not.
#include <benchmark/benchmark.h>

#include "app/scene_setup.h"
#include "control/skills.h"

namespace {

using namespace toolbench;

void BM_PlanPull(benchmark::State& state) {
  static const app::LoadedScene scene = [] {
    app::SceneRequest request;
    request.seed = 1;
    request.tools = {"rake_4"};
    return app::LoadScene(request);
  }();
  const toollib::ToolModel* rake = nullptr;
  for (const auto& m : scene.library) {
    if (m.name == "rake_4") rake = &m;
  }
  // Held as the hand-over puts it: the handle centre in the hand's grasp cylinder.
  const Eigen::Isometry3d X_PT = app::PalmGraspFrame(scene.robot) * app::HandleFrame(rake->handle).inverse();
  const control::ToolEffector effector = app::EffectorOf(*rake);
  const Eigen::Vector3d p_RO = state.range(1) == 0 ? Eigen::Vector3d(-0.45, 0.0, -0.065)
                                                   : Eigen::Vector3d(-0.85, 0.0, -0.065);
  control::PullOptions options;
  options.screening_ipopt_iterations = static_cast<int>(state.range(0));
  options.ik.ipopt_after_failed_presolve = state.range(2) != 0;
  control::PullPlan plan;
  for (auto _ : state) {
    plan = control::PlanPull(scene.robot, scene.robot.HomeQ(), X_PT, effector, p_RO, 0.035, options);
  }
  state.counters["planned"] = plan.complete() ? 1 : 0;
  state.counters["candidates"] = plan.result.candidates;
  state.counters["feasible"] = plan.result.candidates_feasible;
}
BENCHMARK(BM_PlanPull)
    ->ArgsProduct({{10, 0}, {0, 1}, {1, 0}})
    ->ArgNames({"screen_ipopt", "far", "path_ipopt"})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3);

}  // namespace
