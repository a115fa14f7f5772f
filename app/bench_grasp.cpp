#include "app/bench_grasp.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <spdlog/spdlog.h>

#include "app/overview.h"
#include "common/check.h"
#include "sim/scene_composer.h"
#include "sim/world.h"

namespace toolbench::app {
namespace {

// The failure key of a reason ("slip: 7.1 mm" -> "slip"), for the histogram.
std::string ReasonKey(const std::string& reason) { return reason.substr(0, reason.find(':')); }

}  // namespace

void GraspCaseOptions::Validate() const {
  auto fail = [](const char* field, double value) {
    ThrowInvalid("GraspCaseOptions: ", field, " = ", value, " (expected > 0)");
  };
  if (!(hold_time > 0)) fail("hold_time", hold_time);
  if (!(min_lift_m > 0)) fail("min_lift_m", min_lift_m);
  if (!(max_slip_m > 0)) fail("max_slip_m", max_slip_m);
  if (!(sample_period > 0)) fail("sample_period", sample_period);
  if (!(slide_margin_m >= 0)) ThrowInvalid("GraspCaseOptions: slide_margin_m = ", slide_margin_m, " (expected >= 0)");
  grasp.Validate();
}

GraspCaseResult RunGraspCase(const LoadedScene& scene, const std::string& tool, const std::string& cell,
                             std::uint64_t seed, const GraspCaseOptions& options,
                             const std::filesystem::path& frame_png) {
  options.Validate();
  const auto wall_start = std::chrono::steady_clock::now();
  GraspCaseResult out;
  out.tool = tool;
  out.cell = cell;
  std::vector<std::string> names;
  const toollib::ToolModel* model = nullptr;
  for (const auto& t : scene.library) {
    names.push_back(t.name);
    if (t.name == tool) model = &t;
  }
  if (model == nullptr) ThrowInvalid("RunGraspCase: unknown tool '", tool, "'");
  sim::ToolPlacement placement;
  placement.tool = tool;
  placement.cell = cell;
  const sim::ScenePlan plan = sim::PlanScene(scene.spec, names, seed, {placement});
  const sim::ComposedScene composed = sim::ComposeScene(scene.spec, scene.robot, scene.library, plan);
  const std::string body = composed.tools.front().body;
  const std::string& palm = scene.robot.palm_frame;

  sim::World world(composed.mjcf, "grasp-gt " + tool + " " + cell);
  out.settled = world.SettleFreeBodies(scene.spec.physics.settle_time);
  const Eigen::Isometry3d X_RW = composed.X_WR.inverse();
  const Eigen::Isometry3d X_WT_rest = world.ground_truth().Pose(body);
  const Eigen::Isometry3d X_TH = HandleFrame(model->handle);
  const Eigen::Isometry3d X_RH = X_RW * X_WT_rest * X_TH;

  sim::SimRobot robot(world);
  control::GraspOptions grasp_options = options.grasp;
  if (options.slide_along_handle) {
    grasp_options.handle_slide_m =
        std::max(0.0, (model->handle.length - scene.robot.grasp.length) / 2 - options.slide_margin_m);
  }
  if (!frame_png.empty()) {
    // One picture per stage beside the final one: <stem>_<stage>.png.
    grasp_options.on_stage = [&world, &frame_png](const char* stage) {
      std::filesystem::path png = frame_png;
      png.replace_filename(frame_png.stem().string() + "_" + stage + ".png");
      WriteOverviewPng(world, png);
    };
  }
  out.grasp = control::GraspHandle(robot, scene.robot, X_RH, grasp_options);
  auto finish = [&] {
    if (!frame_png.empty()) WriteOverviewPng(world, frame_png);
    out.sim_time = world.time();
    out.wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall_start).count();
    return out;
  };
  if (!world.status().ok) {
    out.reason = "sim_unstable: " + world.status().message;
    return finish();
  }
  // What the arm and hand touch apart from the tool (the rack, the table) when the skill ended.
  for (const auto& [name, pose] : world.ground_truth().X_WB) {
    if (name.rfind("r_", 0) != 0) continue;
    for (const std::string& b : world.ContactingBodies(name)) {
      if (b.rfind("r_", 0) != 0 && b != body) out.robot_contacts.push_back(name + "-" + b);
    }
  }
  if (out.grasp.status != control::GraspStatus::kGrasped) {
    out.reason = std::string(control::ToString(out.grasp.status)) + ": " + out.grasp.reason;
    return finish();
  }

  // The judged hold: sample the tool in the palm frame and its contacts.
  auto tool_in_palm = [&] {
    const sim::GroundTruth truth = world.ground_truth();
    return Eigen::Isometry3d(truth.Pose(palm).inverse() * truth.Pose(body));
  };
  const Eigen::Isometry3d X_PT0 = tool_in_palm();
  const Eigen::Vector3d p_PH0 = X_PT0 * model->handle.center;
  const int samples = std::max(1, static_cast<int>(std::ceil(options.hold_time / options.sample_period)));
  for (int i = 0; i < samples && world.status().ok; ++i) {
    world.Advance(options.sample_period);
    const Eigen::Isometry3d X_PT = tool_in_palm();
    out.slip_m = std::max(out.slip_m, (X_PT * model->handle.center - p_PH0).norm());
    out.slip_rad = std::max(out.slip_rad, Eigen::AngleAxisd(X_PT0.linear().transpose() * X_PT.linear()).angle());
    for (const std::string& b : world.ContactingBodies(body)) {
      if (b.rfind("r_", 0) != 0 &&
          std::find(out.foreign_contacts.begin(), out.foreign_contacts.end(), b) == out.foreign_contacts.end()) {
        out.foreign_contacts.push_back(b);
      }
    }
  }
  out.lift_m = world.ground_truth().Pose(body).translation().z() - X_WT_rest.translation().z();
  out.palm_rise_m = (X_RW * world.ground_truth().Pose(palm)).translation().z() - out.grasp.X_RP_grasp.translation().z();
  if (!world.status().ok) {
    out.reason = "sim_unstable: " + world.status().message;
  } else if (out.lift_m < options.min_lift_m) {
    out.reason = Cat("not_lifted: tool ", out.lift_m * 100, " cm above rest (< ", options.min_lift_m * 100,
                     "), palm ", out.palm_rise_m * 100, " cm above the planned grasp pose");
  } else if (!out.foreign_contacts.empty()) {
    std::string list;
    for (const auto& b : out.foreign_contacts) list += (list.empty() ? "" : ", ") + b;
    out.reason = "foreign_contact: " + list;
  } else if (out.slip_m >= options.max_slip_m) {
    out.reason = Cat("slip: handle moved ", out.slip_m * 1000, " mm in the palm during the hold");
  } else {
    out.success = true;
  }
  return finish();
}

int RunGraspBench(const BenchRequest& request) {
  SceneRequest scene_request;
  scene_request.seed = request.seed;
  const LoadedScene scene = LoadScene(scene_request);
  std::vector<std::string> tools;
  for (const auto& t : scene.library) tools.push_back(t.name);
  std::sort(tools.begin(), tools.end());

  std::filesystem::create_directories(request.out_dir);
  std::ofstream cases(request.out_dir / "cases.jsonl");
  if (!cases) ThrowInvalid("bench grasp-gt: cannot write ", (request.out_dir / "cases.jsonl").string());
  struct Tally {
    int n = 0;
    int ok = 0;
  };
  std::map<std::string, Tally> per_tool, per_cell;
  std::map<std::string, int> reasons;
  std::vector<double> wall_ms, sim_s, slip_ok;
  Tally total;
  int run = 0;
  const int num_cells = static_cast<int>(std::size(sim::kCellNames));
  for (int index = 0; index < static_cast<int>(tools.size()) * num_cells; ++index) {
    if (!InShard(request, index)) continue;
    const std::string& tool = tools[index / num_cells];
    const std::string cell(sim::kCellNames[index % num_cells]);
    if (!Matches(request, tool + "/" + cell)) continue;
    if (request.limit > 0 && run >= request.limit) break;
    ++run;
    const GraspCaseResult r =
        RunGraspCase(scene, tool, cell, request.seed, {},
                     request.frames ? request.out_dir / "frames" / (tool + "_" + cell + ".png") : std::filesystem::path());
    for (Tally* t : {&total, &per_tool[tool], &per_cell[cell]}) {
      ++t->n;
      t->ok += r.success ? 1 : 0;
    }
    if (!r.success) ++reasons[ReasonKey(r.reason)];
    wall_ms.push_back(r.wall_ms);
    sim_s.push_back(r.sim_time);
    if (r.success) slip_ok.push_back(r.slip_m);
    const Eigen::Vector3d p = r.grasp.X_RP_grasp.translation();
    nlohmann::json line = {{"index", index},
                           {"tool", tool},
                           {"cell", cell},
                           {"success", r.success},
                           {"reason", r.reason},
                           {"grasp_status", control::ToString(r.grasp.status)},
                           {"lift_m", r.lift_m},
                           {"slip_m", r.slip_m},
                           {"palm_rise_m", r.palm_rise_m},
                           {"slip_deg", r.slip_rad * 180.0 / M_PI},
                           {"settled", r.settled},
                           {"robot_contacts", r.robot_contacts},
                           {"palm_p_R", {p.x(), p.y(), p.z()}},
                           {"roll_deg", r.grasp.roll_rad * 180.0 / M_PI},
                           {"axis_flipped", r.grasp.axis_flipped},
                           {"slide_m", r.grasp.slide_m},
                           {"candidates_feasible", r.grasp.candidates_feasible},
                           {"plan_ms", r.grasp.plan_ms},
                           {"sim_time_s", r.sim_time},
                           {"wall_ms", r.wall_ms}};
    cases << line.dump() << "\n" << std::flush;
    spdlog::info("grasp-gt {} {}: {} {} (lift {:.3f} m, slip {:.1f} mm, {:.0f} ms)", tool, cell,
                 r.success ? "ok" : "FAIL", r.reason, r.lift_m, r.slip_m * 1000, r.wall_ms);
  }
  auto rate = [](const Tally& t) { return t.n > 0 ? static_cast<double>(t.ok) / t.n : std::nan(""); };
  nlohmann::json summary;
  summary["protocol"] = "grasp-gt";
  summary["seed"] = request.seed;
  summary["shard_index"] = request.shard_index;
  summary["shard_count"] = request.shard_count;
  summary["cases"] = total.n;
  summary["grasp_success_rate"] = rate(total);
  summary["success_criterion"] =
      "tool >= 5 cm above rest, handle moves < 5 mm in the palm frame and touches only r_* bodies during a 2 s hold";
  for (const auto& [name, t] : per_tool) summary["per_tool"][name] = rate(t);
  for (const auto& [name, t] : per_cell) summary["per_cell"][name] = rate(t);
  summary["failure_reasons"] = nlohmann::json::object();
  for (const auto& [name, n] : reasons) summary["failure_reasons"][name] = n;
  summary["slip_m_median_successful"] = Percentile(slip_ok, 50);
  summary["wall_ms_median"] = Percentile(wall_ms, 50);
  summary["sim_time_s_median"] = Percentile(sim_s, 50);
  WriteJson(request.out_dir / "summary.json", summary);
  return 0;
}

}  // namespace toolbench::app
