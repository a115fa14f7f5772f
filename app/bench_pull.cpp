#include "app/bench_pull.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <spdlog/spdlog.h>
#include <Eigen/Geometry>
#include <fmt/format.h>

#include "app/held_tool_view.h"
#include "app/overview.h"
#include "common/check.h"
#include "common/paths.h"
#include "common/rng.h"
#include "sim/renderer.h"
#include "sim/scene_composer.h"
#include "sim/world.h"

namespace toolbench::app {
namespace {

/// summary.md: per family the pull success rate (95 % Wilson intervals) and the mean ball
/// displacement, as a table and as bar charts (per_family.png, displacement.png).
void WritePullReport(const std::filesystem::path& out_dir, const nlohmann::json& summary,
                     const std::map<std::string, Tally>& per_family) {
  std::ostringstream md;
  md << "# pull-gt: pull the ball with each tool from the ground-truth handle\n\n"
     << "Seed " << summary["seed"] << ", cell " << summary["cell"].get<std::string>() << ", " << summary["cases"]
     << " tools run, " << summary["failed_cases"] << " failed to run (see results.jsonl). "
     << summary["success_criterion"].get<std::string>() << ".\n\n"
     << "| family | pull success | 95 % interval | mean displacement | tool grasped | ball grasped | n |\n"
     << "|---|---|---|---|---|---|---|\n";
  BarChart rates;
  rates.title = "pull-gt: ball brought within reach, per tool family (95 % Wilson intervals)";
  rates.x_label = "tool family";
  rates.y_label = "pull success [%]";
  rates.y_max = 112;
  rates.value_labels = true;
  BarChart moved;
  moved.title = "pull-gt: mean ball displacement toward the robot, per tool family";
  moved.x_label = "tool family";
  moved.y_label = "displacement [cm]";
  moved.value_labels = true;
  moved.value_decimals = 1;
  moved.y_min = 0;
  BarSeries displacement;
  std::vector<Tally> tallies;
  for (const auto& [family, t] : per_family) {
    const nlohmann::json& f = summary["per_family"][family];
    auto number = [&](const char* key) { return f[key].is_number() ? f[key].get<double>() : std::nan(""); };
    const auto [lo, hi] = WilsonInterval(t.ok, t.n);
    auto percent = [](double x) { return std::isnan(x) ? std::string("–") : fmt::format("{:.0f} %", 100 * x); };
    md << fmt::format("| {} | {} | {:.0f}–{:.0f} % | {:.1f} cm | {} | {} | {} |\n", family, percent(t.Rate()), 100 * lo,
                      100 * hi, 100 * number("mean_displacement_m"), percent(number("tool_grasp_rate")),
                      percent(number("ball_grasp_success_rate")), t.n);
    rates.categories.push_back(family);
    moved.categories.push_back(family);
    tallies.push_back(t);
    displacement.values.push_back(100 * number("mean_displacement_m"));
    moved.y_min = std::min(moved.y_min, 100 * number("mean_displacement_m") * 1.1);
  }
  if (!per_family.empty()) {
    rates.series.push_back(RateSeries("", tallies));
    WriteBarChartPng(rates, out_dir / "per_family.png");
    moved.series.push_back(displacement);
    WriteBarChartPng(moved, out_dir / "displacement.png");
    md << "\n" << MarkdownImage("pull success per family", "per_family.png") << "\n"
       << MarkdownImage("mean displacement per family", "displacement.png") << "\n";
  }
  if (!summary["failure_reasons"].empty()) {
    md << "| failure | cases |\n|---|---|\n";
    for (const auto& [name, n] : summary["failure_reasons"].items()) md << "| " << name << " | " << n << " |\n";
  }
  WriteTextFile(out_dir / "summary.md", md.str());
}

}  // namespace
void PullCaseOptions::Validate() const {
  if (!sim::IsCellName(cell)) ThrowInvalid("PullCaseOptions: cell = '", cell, "' (expected pos1..pos3, rot0..rot3)");
  if (!(settle_after_s > 0)) ThrowInvalid("PullCaseOptions: settle_after_s = ", settle_after_s, " (expected > 0)");
  if (!(min_lift_m > 0)) ThrowInvalid("PullCaseOptions: min_lift_m = ", min_lift_m, " (expected > 0)");
  if (!(ball_lift_m > 0)) ThrowInvalid("PullCaseOptions: ball_lift_m = ", ball_lift_m, " (expected > 0)");
  if (!(ball_x_range.allFinite() && ball_x_range[0] <= ball_x_range[1])) {
    ThrowInvalid("PullCaseOptions: ball_x_range = (", ball_x_range.transpose(), ") (expected finite lo <= hi)");
  }
  if (!(ball_y_range.allFinite() && ball_y_range[0] <= ball_y_range[1])) {
    ThrowInvalid("PullCaseOptions: ball_y_range = (", ball_y_range.transpose(), ") (expected finite lo <= hi)");
  }
  grasp.Validate();
  pull.Validate();
  put_down.Validate();
  ball_grasp.Validate();
}

PullCaseResult RunPullCase(const LoadedScene& scene, const std::string& tool, std::uint64_t seed,
                           const PullCaseOptions& options, const std::filesystem::path& frames_dir) {
  options.Validate();
  const auto wall_start = std::chrono::steady_clock::now();
  PullCaseResult out;
  out.tool = tool;
  std::vector<std::string> names;
  const toollib::ToolModel* model = nullptr;
  for (const auto& t : scene.library) {
    names.push_back(t.name);
    if (t.name == tool) model = &t;
  }
  if (model == nullptr) ThrowInvalid("RunPullCase: unknown tool '", tool, "'");
  out.family = model->family;
  sim::ToolPlacement placement;
  placement.tool = tool;
  placement.cell = options.cell;
  sim::ScenePlan plan = sim::PlanScene(scene.spec, names, seed, {placement});
  Rng ball_rng(DeriveSeed(seed, "pull-ball"));
  plan.ball_xy = {UniformReal(ball_rng, options.ball_x_range[0], options.ball_x_range[1]),
                  UniformReal(ball_rng, options.ball_y_range[0], options.ball_y_range[1])};
  const sim::ComposedScene composed = sim::ComposeScene(scene.spec, scene.robot, scene.library, plan);
  const std::string body = composed.tools.front().body;
  sim::World world(composed.mjcf, "pull-gt " + tool);
  world.SettleFreeBodies(scene.spec.physics.settle_time);
  const Eigen::Isometry3d X_RW = composed.X_WR.inverse();
  auto ball_R = [&] { return Eigen::Vector3d(X_RW * world.ground_truth().Pose("ball").translation()); };
  auto frame = [&](const std::string& stage) {
    if (!frames_dir.empty()) WriteOverviewPng(world, frames_dir / (tool + "_" + stage + ".png"));
  };
  auto finish = [&](const std::string& reason) {
    out.reason = reason;
    out.sim_time = world.time();
    out.wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall_start).count();
    return out;
  };
  sim::SimRobot robot(world);
  // The palm where the encoders put it (forward kinematics), as the robot knows it.
  const Eigen::Isometry3d X_WT_rest = world.ground_truth().Pose(body);
  const Eigen::Isometry3d X_TH = HandleFrame(model->handle);
  const Eigen::Isometry3d X_RH = X_RW * X_WT_rest * X_TH;
  out.ball_start_R = ball_R();
  out.ball_end_R = out.ball_start_R;
  const double radius = scene.spec.ball.radius;
  out.ball_in_reach_before =
      control::BallInReach(scene.robot, scene.robot.HomeQ(), out.ball_start_R, radius, options.ball_grasp);

  // 1. Grasp from the ground-truth handle as the episode grasps from the perceived one
  // (GraspToolForAction: choked away from the effector, the effector on the +y_P side first).
  const Eigen::Vector3d p_R_effector = X_RW * X_WT_rest * model->effector.center;
  control::GraspOptions grasp_options = options.grasp;
  grasp_options.obstacles = WorkspaceObstacles(scene.spec);
  out.grasp = control::GraspToolForAction(robot, scene.robot, X_RH, p_R_effector,
                                          GripSlide(scene.robot, *model, model->handle), grasp_options);
  frame("1_grasp");
  if (out.grasp.status != control::GraspStatus::kGrasped) {
    return finish(std::string("grasp_") + control::ToString(out.grasp.status) + ": " + out.grasp.reason);
  }
  const double lift = world.ground_truth().Pose(body).translation().z() - X_WT_rest.translation().z();
  if (lift < options.min_lift_m) return finish(Cat("grasp_not_lifted: tool ", lift * 100, " cm above rest"));
  out.grasped = true;

  // 2. Pull. The in-hand pose is what the robot knows: the planned palm pose at the grasp and the
  // handle pose it grasped.
  Eigen::Isometry3d X_PT = out.grasp.X_RP_grasp.inverse() * X_RH * X_TH.inverse();
  out.ball_moved_by_grasp_m = (ball_R() - out.ball_start_R).norm();
  out.in_hand_effector_dir_P = (X_PT * model->effector.center).normalized();
  out.in_hand_working_dir_P = X_PT.linear() * Eigen::Vector3d::UnitX();
  {
    // How the tool sits in the hand after the lift (ground truth) against what the robot assumes.
    const Eigen::Isometry3d X_PT_truth =
        PalmPoseFromEncoders(scene.robot, robot).inverse() * X_RW * world.ground_truth().Pose(body);
    const InHandError after_lift = InHandPoseError(X_PT, X_PT_truth, model->effector.center);
    out.lift_slip_m = after_lift.effector_m;
    out.lift_pivot_deg = after_lift.rotation_deg;
  }
  if (options.inspect_held_tool) {
    // The robot's eye, as the episode has it: rendered frames, camera pose from the encoders.
    sim::GlContext gl;
    sim::Renderer eye(gl, world, sim::RendererOptions{});
    auto see = [&] {
      RgbdFrame frame = eye.Render(world, DeriveSeed(seed, "in-hand frame"));
      frame.X_RC = CameraPoseFromEncoders(scene.robot, robot);
      return frame;
    };
    const HeldToolView view = InspectHeldTool(robot, scene.robot, see, *model, X_PT);
    X_PT = view.X_PT;
    out.inspected = view.estimate.ok;
    out.inspect_reason = view.estimate.reason;
    const Eigen::Isometry3d X_PT_truth = view.X_RP.inverse() * X_RW * world.ground_truth().Pose(body);
    const InHandError used = InHandPoseError(X_PT, X_PT_truth, model->effector.center);
    out.used_pose_error_deg = used.rotation_deg;
    out.used_effector_error_m = used.effector_m;
  }
  if (options.inspect_held_tool) frame("1b_inspected");  // its own GL context: after the eye's is gone
  out.ball_start_R = ball_R();
  control::PullOptions pull_options = options.pull;
  pull_options.support_xy = TableTopArea(scene.spec);
  pull_options.fixtures = RackObstacles(scene.spec);
  // Where the tool really is at the start of the drag (ground truth), against where the plan put
  // it, and the palm from the encoders against the tool: sag of the arm vs slip in the hand.
  int stage_index = 0;
  Eigen::Isometry3d X_RT_at_start = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d X_RP_at_start = Eigen::Isometry3d::Identity();
  bool reached_start = false;
  pull_options.on_stage = [&](const char* stage) {
    if (std::string(stage) == "at_start") {
      reached_start = true;
      out.ball_moved_before_drag_m = (ball_R() - out.ball_start_R).norm();
      X_RT_at_start = X_RW * world.ground_truth().Pose(body);
      X_RP_at_start = PalmPoseFromEncoders(scene.robot, robot);
    }
    if (!frames_dir.empty()) frame("2" + std::string(1, static_cast<char>('a' + stage_index++)) + "_pull_" + stage);
  };
  out.pull = control::PullObject(robot, scene.robot, X_PT, EffectorOf(*model), out.ball_start_R, radius, pull_options);
  if (reached_start) {
    const Eigen::Vector3d p_TE = model->effector.center;
    out.start_effector_error_m = (X_RT_at_start * p_TE - out.pull.X_RT_start * p_TE).norm();
    out.start_slip_m = (X_RT_at_start * p_TE - X_RP_at_start * X_PT * p_TE).norm();
  }
  robot.Wait(options.settle_after_s);
  frame("2_pull");
  out.ball_end_R = ball_R();
  Eigen::Vector3d u(-out.ball_start_R.x(), -out.ball_start_R.y(), 0.0);
  u.normalize();
  out.displacement_m = (out.ball_end_R - out.ball_start_R).dot(u);
  out.ball_in_reach =
      control::BallInReach(scene.robot, scene.robot.HomeQ(), out.ball_end_R, radius, options.ball_grasp);
  if (!world.status().ok) return finish("sim_unstable: " + world.status().message);
  std::string reason;
  if (out.pull.status != control::PullStatus::kPulled) {
    reason = std::string("pull_") + control::ToString(out.pull.status) + ": " + out.pull.reason;
  } else if (!out.ball_in_reach) {
    reason = Cat("ball_out_of_reach: moved ", out.displacement_m * 100, " cm toward the robot");
  }
  if (!options.put_down_and_grasp_ball || out.pull.status == control::PullStatus::kLostTool) return finish(reason);

  // 3. Put the tool down at a free place on the table, then grasp the ball if it is in reach.
  out.put_down = PutDownOnTable(robot, scene.robot, scene.spec, X_PT, *model, {ball_R()}, options.put_down).put.placed;
  frame("3_put_down");
  if (out.ball_in_reach && out.put_down) {
    out.ball_grasp_tried = true;
    const Eigen::Vector3d p_ball = ball_R();
    control::BallGraspOptions ball_grasp = options.ball_grasp;
    ball_grasp.obstacles = WorkspaceObstacles(scene.spec);  // as the episode's ball grasp
    const control::GraspResult g = control::GraspBall(robot, scene.robot, p_ball, radius, ball_grasp);
    robot.Wait(1.0);  // held for a second more after the skill's own hold
    out.ball_lift_m = ball_R().z() - p_ball.z();
    out.ball_grasped = g.status == control::GraspStatus::kGrasped && out.ball_lift_m >= options.ball_lift_m;
    out.ball_grasp_status = control::ToString(g.status);
    out.ball_grasp_reason = g.reason;
    out.ball_crossings_blocked = g.paths_blocked;
    frame("4_ball");
  }
  return finish(reason);
}

int RunPullBench(const BenchRequest& request) {
  const SceneRequest scene_request = BenchScene(request, request.seed);
  const LoadedScene scene = LoadScene(scene_request);  // built once; the case processes inherit it
  const PullCaseOptions options;
  const std::vector<SweepCase> cases = ToolCellCases(SortedToolNames(scene.library), {options.cell});
  auto run_case = [&](const SweepCase& c) {
    const std::string tool = c.params.at("tool");
    const std::uint64_t seed = DeriveSeed(request.seed, "pull/" + tool);
    const PullCaseResult r =
        RunPullCase(scene, tool, seed, options, request.frames ? request.out_dir / "frames" : std::filesystem::path());
    spdlog::info("pull-gt {}: ball moved {:.1f} cm toward the robot, {} ({}) [{:.0f} ms]", tool, r.displacement_m * 100,
                 r.ball_in_reach ? "in reach" : "out of reach", r.reason, r.wall_ms);
    auto vec = [](const Eigen::Vector3d& v) { return nlohmann::json{v.x(), v.y(), v.z()}; };
    return nlohmann::json{{"tool", tool},
                          {"family", r.family},
                          {"cell", options.cell},
                          {"seed", seed},
                          {"grasped", r.grasped},
                          {"grasp_status", control::ToString(r.grasp.status)},
                          {"pull_status", control::ToString(r.pull.status)},
                          {"reason", r.reason},
                          {"ball_start_R", vec(r.ball_start_R)},
                          {"ball_end_R", vec(r.ball_end_R)},
                          {"displacement_m", r.displacement_m},
                          {"ball_in_reach_before", r.ball_in_reach_before},
                          {"ball_in_reach", r.ball_in_reach},
                          {"planned_drag_m", r.pull.planned_drag_m},
                          {"sag_offset_rad", r.pull.sag_offset_rad},
                          {"start_palm_error_m", r.pull.start_palm_error_m},
                          {"planned_lift_m", r.pull.planned_lift_m},
                          {"pull_elevation_deg", r.pull.elevation_rad * 180 / M_PI},
                          {"pull_yaw_deg", r.pull.yaw_rad * 180 / M_PI},
                          {"pull_roll_deg", r.pull.roll_rad * 180 / M_PI},
                          {"pull_candidates_feasible", r.pull.candidates_feasible},
                          {"pull_candidates_blocked", r.pull.candidates_blocked},
                          {"pull_start_distance_m", r.pull.start_distance_m},
                          {"pull_turn_deg", r.pull.pull_turn_rad * 180 / M_PI},
                          {"working_cos", r.pull.working_cos},
                          {"pull_plan_ms", r.pull.plan_ms},
                          {"pull_motion_s", r.pull.motion_s},
                          {"grasp_roll_deg", r.grasp.roll_rad * 180 / M_PI},
                          {"grasp_axis_flipped", r.grasp.axis_flipped},
                          {"grasp_regrasps", r.grasp.regrasps},
                          {"grasp_slide_m", r.grasp.slide_m},
                          {"in_hand_effector_dir_P", vec(r.in_hand_effector_dir_P)},
                          {"in_hand_working_dir_P", vec(r.in_hand_working_dir_P)},
                          {"inspected", r.inspected},
                          {"inspect_reason", r.inspect_reason},
                          {"used_pose_error_deg", r.used_pose_error_deg},
                          {"used_effector_error_m", r.used_effector_error_m},
                          {"lift_slip_m", r.lift_slip_m},
                          {"lift_pivot_deg", r.lift_pivot_deg},
                          {"start_effector_error_m", r.start_effector_error_m},
                          {"start_slip_m", r.start_slip_m},
                          {"ball_moved_by_grasp_m", r.ball_moved_by_grasp_m},
                          {"ball_moved_before_drag_m", r.ball_moved_before_drag_m},
                          {"put_down", r.put_down},
                          {"ball_grasp_tried", r.ball_grasp_tried},
                          {"ball_grasped", r.ball_grasped},
                          {"ball_grasp_status", r.ball_grasp_status},
                          {"ball_grasp_reason", r.ball_grasp_reason},
                          {"ball_crossings_blocked", r.ball_crossings_blocked},
                          {"ball_lift_m", r.ball_lift_m},
                          {"sim_time_s", r.sim_time},
                          {"wall_ms", r.wall_ms}};
  };
  nlohmann::json info;
  info["cell"] = options.cell;
  ReportPull(request, RunSweep(SweepOptionsFor(request, "pull-gt", info), cases, run_case));
  return 0;
}

void ReportPull(const BenchRequest& request, const std::vector<SweepLine>& lines) {
  struct PullTally {
    int n = 0, in_reach = 0, grasped = 0, pulled = 0, ball_tried = 0, ball_ok = 0;
    double displacement = 0.0;
  };
  std::map<std::string, PullTally> per_family;
  std::map<std::string, int> reasons;
  PullTally total;
  std::vector<double> plan_ms;  // PullResult::plan_ms of every case that reached the pull
  std::string cell = kPullCell;
  int failed = 0;
  for (const SweepLine& line : lines) {
    if (!line.value("ok", false)) {
      ++failed;
      continue;
    }
    const nlohmann::json& r = line["result"];
    cell = r.value("cell", cell);
    for (PullTally* t : {&total, &per_family[r.at("family").get<std::string>()]}) {
      ++t->n;
      t->in_reach += r.at("ball_in_reach").get<bool>() ? 1 : 0;
      t->grasped += r.at("grasped").get<bool>() ? 1 : 0;
      t->pulled += r.at("pull_status").get<std::string>() == control::ToString(control::PullStatus::kPulled) ? 1 : 0;
      t->ball_tried += r.at("ball_grasp_tried").get<bool>() ? 1 : 0;
      t->ball_ok += r.at("ball_grasped").get<bool>() ? 1 : 0;
      t->displacement += r.at("displacement_m").get<double>();
    }
    const std::string reason = r.at("reason").get<std::string>();
    if (!reason.empty()) ++reasons[reason.substr(0, reason.find(':'))];
    if (r.at("grasped").get<bool>() && r.contains("pull_plan_ms")) {
      plan_ms.push_back(r.at("pull_plan_ms").get<double>());
    }
  }
  auto ratio = [](int k, int n) { return n > 0 ? static_cast<double>(k) / n : std::nan(""); };
  auto tally_json = [&](const PullTally& t) {
    return nlohmann::json{{"cases", t.n},
                          {"mean_displacement_m", t.n > 0 ? t.displacement / t.n : std::nan("")},
                          {"pull_success_rate", ratio(t.in_reach, t.n)},
                          {"tool_grasp_rate", ratio(t.grasped, t.n)},
                          {"pull_executed_rate", ratio(t.pulled, t.n)},
                          {"ball_grasp_success_rate", ratio(t.ball_ok, t.ball_tried)}};
  };
  nlohmann::json summary = tally_json(total);
  summary["protocol"] = "pull-gt";
  summary["seed"] = request.seed;
  summary["shard_index"] = request.shard_index;
  summary["shard_count"] = request.shard_count;
  summary["failed_cases"] = failed;
  summary["cell"] = cell;
  if (!plan_ms.empty()) {
    summary["pull_plan_ms_median"] = Percentile(plan_ms, 50);
    summary["pull_plan_ms_max"] = *std::max_element(plan_ms.begin(), plan_ms.end());
  }
  summary["success_criterion"] =
      "pull success: after the pull the ball is within reach, i.e. a palm pose grasping it from above (or tilted "
      "toward the robot up to 57 deg) has a converged IK from the home posture; displacement = ball motion along the "
      "horizontal direction from its start toward the robot's vertical axis; ball grasp: ball >= 3 cm above its "
      "rest height 1 s after the grasp skill's hold";
  for (const auto& [name, t] : per_family) summary["per_family"][name] = tally_json(t);
  summary["failure_reasons"] = nlohmann::json::object();
  for (const auto& [name, n] : reasons) summary["failure_reasons"][name] = n;
  WriteJson(request.out_dir / "summary.json", summary);
  std::map<std::string, Tally> family_tallies;
  for (const auto& [name, t] : per_family) family_tallies[name] = Tally{t.n, t.in_reach};
  WritePullReport(request.out_dir, summary, family_tallies);
}

}  // namespace toolbench::app
