#include "app/bench_grasp.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "app/overview.h"
#include "common/check.h"
#include "common/paths.h"
#include "sim/scene_composer.h"
#include "sim/world.h"

namespace toolbench::app {
namespace {

// The failure key of a reason ("slip: 7.1 mm" -> "slip"), for the histogram.
std::string ReasonKey(const std::string& reason) { return reason.substr(0, reason.find(':')); }

/// summary.md with the success rate per cell and per tool (95 % Wilson intervals), as tables
/// and as bar charts (per_cell.png, per_tool.png).
void WriteGraspReport(const std::filesystem::path& out_dir, const nlohmann::json& summary,
                      const std::map<std::string, Tally>& per_cell, const std::map<std::string, Tally>& per_tool) {
  std::ostringstream md;
  md << "# grasp-gt: grasp, lift and hold from the ground-truth handle\n\n"
     << "Seed " << summary["seed"] << ", " << summary["cases"] << " cases run, " << summary["failed_cases"]
     << " failed to run (see results.jsonl). Success: " << summary["success_criterion"].get<std::string>() << ".\n\n"
     << (summary["start"] == "rack_look"
             ? "The arm started as in an episode, after the look at the rack (torso turned, hand beside the hip).\n\n"
             : "The arm started from the home posture.\n\n")
     << fmt::format(
            "Grasped {} of {} cells ({:.0f} %). {} cells have no palm pose on the handle within the arm's "
            "reach (grasp status `unreachable`: IK with the approach filters); of the other {}, {:.0f} % "
            "were grasped.\n\n",
            summary["cells_grasped"].get<int>(), summary["cases"].get<int>(),
            100 * summary["grasp_success_rate"].get<double>(), summary["cells_out_of_reach"].get<int>(),
            summary["cases"].get<int>() - summary["cells_out_of_reach"].get<int>(),
            100 * summary["grasp_success_rate_within_reach"].get<double>())
     << fmt::format(
            "In the hold of the cells grasped, the handle moved {:.1f} mm in the hand and turned {:.1f} deg "
            "(medians; the turn's 90th percentile {:.1f} deg, largest {:.1f} deg). Judged by the handle's "
            "centre instead of the point held (sessions before 48), {} cells were grasped.\n\n",
            1000 * summary["slip_m_median_successful"].get<double>(),
            summary["slip_deg_median_successful"].get<double>(), summary["slip_deg_p90_successful"].get<double>(),
            summary["slip_deg_max_successful"].get<double>(), summary["cells_grasped_by_handle_centre"].get<int>());
  auto section = [&](const std::string& what, const std::map<std::string, Tally>& tallies, const std::string& png) {
    BarChart chart;
    chart.title = "grasp-gt: grasp success per " + what + " (95 % Wilson intervals)";
    chart.x_label = what;
    chart.y_label = "grasp success [%]";
    chart.y_max = 112;
    std::vector<Tally> values;
    md << "| " << what << " | success | 95 % interval | n |\n|---|---|---|---|\n";
    for (const auto& [name, t] : tallies) {
      chart.categories.push_back(name);
      values.push_back(t);
      const auto [lo, hi] = WilsonInterval(t.ok, t.n);
      md << fmt::format("| {} | {:.0f} % | {:.0f}–{:.0f} % | {} |\n", name, 100 * t.Rate(), 100 * lo, 100 * hi, t.n);
    }
    if (tallies.empty()) return;
    chart.series.push_back(RateSeries("", values));
    chart.value_labels = tallies.size() <= 12;
    WriteBarChartPng(chart, out_dir / png);
    md << "\n" << MarkdownImage("grasp success per " + what, png) << "\n";
  };
  section("cell", per_cell, "per_cell.png");
  section("tool", per_tool, "per_tool.png");
  if (!summary["failure_reasons"].empty()) {
    md << "| failure | cases |\n|---|---|\n";
    for (const auto& [name, n] : summary["failure_reasons"].items()) md << "| " << name << " | " << n << " |\n";
  }
  WriteTextFile(out_dir / "summary.md", md.str());
}

// "robot body-other body" for every right-arm or hand body ("r_" prefix) touching a non-robot
// body other than `except`.
std::vector<std::string> RobotContacts(sim::World& world, const sim::GroundTruth& truth,
                                       const std::string& except = "") {
  std::vector<std::string> contacts;
  for (const auto& [name, pose] : truth.X_WB) {
    if (name.rfind("r_", 0) != 0) continue;
    for (const std::string& b : world.ContactingBodies(name)) {
      if (b.rfind("r_", 0) != 0 && b != except) contacts.push_back(name + "-" + b);
    }
  }
  return contacts;
}

// {stage: {"offset_P_mm": [x, y, z], "angle_deg": a}} of GraspCaseResult::handle_in_hand.
nlohmann::json HandleInHandJson(const std::vector<GraspCaseResult::HandleInHand>& stages) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& h : stages) {
    const Eigen::Vector3d mm = 1000 * h.offset_P;
    j[h.stage] = {{"offset_P_mm", {mm.x(), mm.y(), mm.z()}},
                  {"angle_deg", h.angle_rad * 180.0 / M_PI},
                  {"handle_moved_mm", 1000 * h.handle_moved_m},
                  {"palm_off_plan_mm", 1000 * h.palm_off_plan_m},
                  {"contacts", h.contacts}};
  }
  return j;
}

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
  if (options.from_rack_look) LookAt(robot, scene.robot, RackViewTarget(scene.spec), /*arm_down=*/true);
  control::GraspOptions grasp_options = options.grasp;
  grasp_options.obstacles = WorkspaceObstacles(scene.spec);
  if (options.slide_along_handle) {
    grasp_options.handle_slide = GripSlide(scene.robot, *model, model->handle, options.slide_margin_m);
  }
  // At each stage of the skill: where the true handle axis passes the hand's grasp cylinder, and
  // with frames, one picture per stage beside the final one (<stem>_<stage>.png).
  const robot::GraspSpec& hand = scene.robot.grasp;
  grasp_options.on_stage = [&](const char* stage) {
    const sim::GroundTruth truth = world.ground_truth();
    const Eigen::Isometry3d X_WP = truth.Pose(palm);
    const Eigen::Isometry3d X_PT = X_WP.inverse() * truth.Pose(body);
    const Eigen::Vector3d d_P = (X_PT.linear() * model->handle.axis).normalized();
    const Eigen::Vector3d from_axis = hand.center - X_PT * model->handle.center;
    GraspCaseResult::HandleInHand h;
    h.stage = stage;
    h.offset_P = -(from_axis - from_axis.dot(d_P) * d_P);
    h.angle_rad = std::acos(std::min(1.0, std::abs(d_P.dot(hand.axis.normalized()))));
    h.handle_moved_m = (truth.Pose(body) * model->handle.center - X_WT_rest * model->handle.center).norm();
    h.p_RP = X_RW * X_WP.translation();  // compared with the plan when it is known
    h.contacts = RobotContacts(world, truth);
    out.handle_in_hand.push_back(h);
    if (frame_png.empty()) return;
    std::filesystem::path png = frame_png;
    png.replace_filename(frame_png.stem().string() + "_" + stage + ".png");
    WriteOverviewPng(world, png);
  };
  out.grasp = control::GraspHandle(robot, scene.robot, X_RH, grasp_options);
  for (auto& h : out.handle_in_hand) h.palm_off_plan_m = (h.p_RP - out.grasp.X_RP_grasp.translation()).norm();
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
  out.robot_contacts = RobotContacts(world, world.ground_truth(), body);
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
  // Where the hand holds the tool when the hold begins: the point of the handle's axis line
  // nearest the hand's grasp centre (a handle held by the fingertips sits off that centre). The
  // handle centre lies as far from it as the grasp slid along the bar (a stick held 14 cm down
  // its handle), and a turn of the tool about the grip moves the centre that much more.
  const Eigen::Vector3d p_TC = X_PT0.inverse() * scene.robot.grasp.center;
  const Eigen::Vector3d& axis_T = model->handle.axis;
  const Eigen::Vector3d p_TG = model->handle.center + (p_TC - model->handle.center).dot(axis_T) * axis_T;
  const Eigen::Vector3d p_PG0 = X_PT0 * p_TG;
  const int samples = std::max(1, static_cast<int>(std::ceil(options.hold_time / options.sample_period)));
  for (int i = 0; i < samples && world.status().ok; ++i) {
    world.Advance(options.sample_period);
    const Eigen::Isometry3d X_PT = tool_in_palm();
    out.slip_m = std::max(out.slip_m, (X_PT * p_TG - p_PG0).norm());
    out.handle_centre_slip_m = std::max(out.handle_centre_slip_m, (X_PT * model->handle.center - p_PH0).norm());
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
    out.reason = Cat("slip: the handle moved ", out.slip_m * 1000, " mm in the hand during the hold");
  } else {
    out.success = true;
  }
  return finish();
}

int RunGraspBench(const BenchRequest& request) {
  const SceneRequest scene_request = BenchScene(request, request.seed);
  const LoadedScene scene = LoadScene(scene_request);  // built once; the case processes inherit it
  std::vector<std::string> cells;
  for (std::string_view cell : sim::kCellNames) cells.emplace_back(cell);
  const std::vector<SweepCase> cases = ToolCellCases(SortedToolNames(scene.library), cells);
  GraspCaseOptions case_options;
  case_options.from_rack_look = request.from_rack_look;
  auto run_case = [&](const SweepCase& c) {
    const std::string tool = c.params.at("tool");
    const std::string cell = c.params.at("cell");
    const GraspCaseResult r =
        RunGraspCase(scene, tool, cell, request.seed, case_options,
                     request.frames ? request.out_dir / "frames" / (tool + "_" + cell + ".png") : std::filesystem::path());
    spdlog::info("grasp-gt {} {}: {} {} (lift {:.3f} m, slip {:.1f} mm, {:.0f} ms)", tool, cell,
                 r.success ? "ok" : "FAIL", r.reason, r.lift_m, r.slip_m * 1000, r.wall_ms);
    const Eigen::Vector3d p = r.grasp.X_RP_grasp.translation();
    return nlohmann::json{{"tool", tool},
                          {"cell", cell},
                          {"start", request.from_rack_look ? "rack_look" : "home"},
                          {"success", r.success},
                          {"reason", r.reason},
                          {"grasp_status", control::ToString(r.grasp.status)},
                          {"lift_m", r.lift_m},
                          {"slip_m", r.slip_m},
                          {"handle_centre_slip_m", r.handle_centre_slip_m},
                          {"palm_rise_m", r.palm_rise_m},
                          {"slip_deg", r.slip_rad * 180.0 / M_PI},
                          {"settled", r.settled},
                          {"robot_contacts", r.robot_contacts},
                          {"palm_p_R", {p.x(), p.y(), p.z()}},
                          {"roll_deg", r.grasp.roll_rad * 180.0 / M_PI},
                          {"axis_flipped", r.grasp.axis_flipped},
                          {"slide_m", r.grasp.slide_m},
                          {"candidates_feasible", r.grasp.candidates_feasible},
                          {"paths_blocked", r.grasp.paths_blocked},
                          {"transfer_raised", r.grasp.transfer_raised},
                          {"transfer_route", r.grasp.transfer_route},
                          {"candidates_touching", r.grasp.candidates_touching},
                          {"last_touching", r.grasp.last_touching},
                          {"hand_touches_fixture", r.grasp.hand_touches_fixture},
                          {"hand_touch_depth_m", r.grasp.hand_touch_depth_m},
                          {"plan_ms", r.grasp.plan_ms},
                          {"handle_in_hand", HandleInHandJson(r.handle_in_hand)},
                          {"sim_time_s", r.sim_time},
                          {"wall_ms", r.wall_ms}};
  };
  ReportGrasp(request, RunSweep(SweepOptionsFor(request, "grasp-gt", {{"from_rack_look", request.from_rack_look}}),
                                cases, run_case));
  return 0;
}

void ReportGrasp(const BenchRequest& request, const std::vector<SweepLine>& lines) {
  std::map<std::string, Tally> per_tool, per_cell;
  std::map<std::string, int> reasons;
  std::vector<double> wall_ms, sim_s, slip_ok, turn_ok;
  Tally total;
  int by_handle_centre = 0;  // cells grasped had the handle centre been judged, not the point held
  int failed = 0;
  for (const SweepLine& line : lines) {
    if (!line.value("ok", false)) {
      ++failed;
      continue;
    }
    const nlohmann::json& r = line["result"];
    const bool success = r.at("success").get<bool>();
    for (Tally* t : {&total, &per_tool[r.at("tool").get<std::string>()], &per_cell[r.at("cell").get<std::string>()]}) {
      t->Add(success);
    }
    if (!success) ++reasons[ReasonKey(r.at("reason").get<std::string>())];
    wall_ms.push_back(r.at("wall_ms").get<double>());
    sim_s.push_back(r.at("sim_time_s").get<double>());
    if (success) {
      slip_ok.push_back(r.at("slip_m").get<double>());
      turn_ok.push_back(r.value("slip_deg", std::nan("")));
    }
    // Every criterion but the slip met (a success, or a failure for slip alone): judged by the
    // handle centre's displacement instead.
    const bool slip_judged = success || ReasonKey(r.at("reason").get<std::string>()) == "slip";
    if (slip_judged && r.value("handle_centre_slip_m", r.value("slip_m", 0.0)) < GraspCaseOptions{}.max_slip_m) {
      ++by_handle_centre;
    }
  }
  nlohmann::json summary;
  summary["protocol"] = "grasp-gt";
  summary["seed"] = request.seed;
  summary["shard_index"] = request.shard_index;
  summary["shard_count"] = request.shard_count;
  summary["cases"] = total.n;
  summary["failed_cases"] = failed;
  summary["grasp_success_rate"] = total.Rate();
  // Cells whose handle no sampled palm pose reaches (IK, with the planner's approach filters):
  // upside-down long tools (rot2) hold their handle beyond the arm, where the episode asks for a
  // hand-over. The rate over the other cells is the grasp's own.
  const int out_of_reach = reasons.count("unreachable") ? reasons.at("unreachable") : 0;
  summary["cells_grasped"] = total.ok;
  summary["cells_out_of_reach"] = out_of_reach;
  summary["grasp_success_rate_within_reach"] = Tally{total.n - out_of_reach, total.ok}.Rate();
  // Where the arm started (one value per run; "home" for lines written before it was recorded).
  std::string start = "home";
  for (const SweepLine& line : lines) {
    if (line.value("ok", false)) start = line["result"].value("start", std::string("home"));
  }
  summary["start"] = start;
  summary["success_criterion"] =
      "tool >= 5 cm above rest; during a 2 s hold, its handle axis point nearest the hand's grasp centre moves "
      "< 5 mm in the palm frame and it touches only r_* bodies";
  for (const auto& [name, t] : per_tool) summary["per_tool"][name] = t.Rate();
  for (const auto& [name, t] : per_cell) summary["per_cell"][name] = t.Rate();
  summary["failure_reasons"] = nlohmann::json::object();
  for (const auto& [name, n] : reasons) summary["failure_reasons"][name] = n;
  summary["slip_m_median_successful"] = Percentile(slip_ok, 50);
  summary["slip_deg_median_successful"] = Percentile(turn_ok, 50);
  summary["slip_deg_p90_successful"] = Percentile(turn_ok, 90);
  summary["slip_deg_max_successful"] = Percentile(turn_ok, 100);
  summary["cells_grasped_by_handle_centre"] = by_handle_centre;
  summary["wall_ms_median"] = Percentile(wall_ms, 50);
  summary["sim_time_s_median"] = Percentile(sim_s, 50);
  WriteJson(request.out_dir / "summary.json", summary);
  WriteGraspReport(request.out_dir, summary, per_cell, per_tool);
}

}  // namespace toolbench::app
