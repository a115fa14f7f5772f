#include "app/explore.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <regex>
#include <set>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "app/affordance.h"
#include "app/bench.h"
#include "app/perceive.h"
#include "app/scene_setup.h"
#include "app/sweep.h"
#include "common/check.h"
#include "common/rng.h"
#include "control/skills.h"
#include "perception/analysis.h"
#include "perception/parts.h"
#include "sim/scene_composer.h"
#include "sim/world.h"

namespace toolbench::app {
namespace {

/// Largest displacement a label takes when the ball left the table [m]: the pull skill's planned
/// drag (0.25 m) plus 5 cm.
constexpr double kMaxLabel_m = 0.30;

nlohmann::json Vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

/// Everything a trial needs that does not change between trials; built once in the parent so
/// that the forked children inherit it.
struct ExploreContext {
  LoadedScene base;
  std::vector<std::string> names;
  std::map<std::string, const toollib::ToolModel*> models;
  perception::ShapeOptions shape_options;
  perception::ShapeCache shapes;
};

/// One trial: hand the tool over at the case's roll, act on the ball, measure.
nlohmann::json RunTrial(ExploreContext& ctx, const SweepCase& c) {
  const auto wall_start = std::chrono::steady_clock::now();
  const std::string tool = c.params.at("tool");
  const std::string action = c.params.at("action");
  const double roll_deg = c.params.at("roll_deg");
  const std::uint64_t seed = c.params.at("seed");
  const toollib::ToolModel& model = *ctx.models.at(tool);
  const sim::SceneSpec& spec = ctx.base.spec;
  const robot::RobotDescription& desc = ctx.base.robot;

  nlohmann::json out;
  out["tool"] = tool;
  out["family"] = model.family;
  out["action"] = action;
  out["roll_deg"] = roll_deg;
  out["seed"] = seed;
  out["labelled"] = false;

  // The regressor's input, from perception's shape analysis of the library model (what the
  // episode uses for a recognised tool) and the pose the hand-over puts the tool in.
  const perception::ModelShape& shape = ctx.shapes.Get(model, ctx.shape_options);
  // Held as the robot's grasp and the hand-over hold it: choked toward the end away from the
  // effector (ChokedHandleFrame).
  const Eigen::Isometry3d X_TH =
      ChokedHandleFrame(desc, perception::SidecarHandleFrame(model), model.effector.center, model.handle.length);
  const Eigen::Isometry3d X_GT = HeldToolPose(X_TH, roll_deg * M_PI / 180.0);
  const Eigen::Isometry3d X_PT = PalmGraspFrame(desc) * X_GT;
  if (shape.status != perception::ShapeStatus::kOk) {
    out["failure"] = std::string("shape_analysis: ") + shape.reason;
    return out;
  }
  const Eigen::VectorXd x = AffordanceFeatures(shape.parts, shape.handle.part, shape.features, X_GT);
  out["features"] = std::vector<double>(x.data(), x.data() + x.size());

  sim::ToolPlacement placement;
  placement.tool = tool;
  placement.cell = "pos2";
  sim::ScenePlan plan = sim::PlanScene(spec, ctx.names, seed, {placement});
  Rng ball_rng(DeriveSeed(seed, "explore-ball"));
  plan.ball_xy = {UniformReal(ball_rng, spec.ball.x_range[0], spec.ball.x_range[1]),
                  UniformReal(ball_rng, spec.ball.y_range[0], spec.ball.y_range[1])};
  const sim::ComposedScene composed = sim::ComposeScene(spec, desc, ctx.base.library, plan);
  const std::string body = composed.tools.front().body;
  sim::World world(composed.mjcf, "explore " + c.id);
  world.SettleFreeBodies(spec.physics.settle_time);
  sim::SimRobot robot(world);
  const Eigen::Isometry3d X_RW = composed.X_WR.inverse();
  auto ball_R = [&] { return Eigen::Vector3d(X_RW * world.ground_truth().Pose(composed.ball_body).translation()); };

  // A person puts the tool in the open hand at the trial's roll (the recorded teleport).
  const Eigen::Vector3d p_R_tool = X_RW * world.ground_truth().Pose(body).translation();
  const control::HandOverResult handed = control::HandOver(robot, desc, p_R_tool, [&](const Eigen::Isometry3d& X_RP) {
    world.TeleportFreeBody(body, composed.X_WR * X_RP * X_PT);
  });
  out["hand_over_holding"] = handed.holding;
  if (!handed.holding) {
    out["failure"] = "hand_over: " + handed.reason;
    return out;
  }

  // The action, aimed at the ball's true position (the supervisor's: this isolates the
  // affordance from ball detection, as pull-gt does).
  const Eigen::Vector3d start = ball_R();
  const double radius = spec.ball.radius;
  control::PullOptions options;
  options.action = *control::ParseToolAction(action);  // validated by ExploreRequest::Validate
  const Eigen::Vector3d u = control::ActionDirection(options.action, start);
  // The tool pivots and slides as the fingers close on it (up to tens of degrees for thin
  // handles): the action is planned with the pose it really has in the hand (the supervisor's,
  // as the ball's; the episode looks at it instead), while the features keep the pose the
  // hand-over meant, which is all the episode knows when it chooses a tool.
  const Eigen::Isometry3d X_PT_held =
      world.ground_truth().Pose(desc.palm_frame).inverse() * world.ground_truth().Pose(body);
  out["held_pivot_deg"] = Eigen::AngleAxisd(X_PT.linear().transpose() * X_PT_held.linear()).angle() * 180.0 / M_PI;
  out["held_slide_m"] = (X_PT_held.translation() - X_PT.translation()).norm();
  const control::PullResult pulled =
      control::PullObject(robot, desc, X_PT_held, EffectorOf(model), start, radius, options);
  robot.Wait(0.5);  // let the ball come to rest
  const Eigen::Vector3d end = ball_R();
  Eigen::Vector3d d = end - start;
  d.z() = 0.0;
  out["ball_start_R"] = Vec3(start);
  out["ball_end_R"] = Vec3(end);
  out["displacement_R"] = Vec3(d);
  out["direction_R"] = Vec3(u);
  // A ball knocked off the table flies or rolls on the floor: its travel says nothing more about
  // the tool, so the label saturates at the table's scale (the planned drag plus a margin).
  const bool on_table = std::abs(end.z() - start.z()) < radius;
  const double along = std::clamp(d.dot(u), -kMaxLabel_m, kMaxLabel_m);
  out["ball_on_table"] = on_table;
  out["displacement_along_raw_m"] = d.dot(u);
  out["displacement_along_m"] = on_table ? d.dot(u) : along;
  out["displacement_across_m"] = d.dot(Eigen::Vector3d::UnitZ().cross(u));
  out["action_status"] = control::ToString(pulled.status);
  out["action_reason"] = pulled.reason;
  out["planned_m"] = pulled.planned_drag_m;
  out["plan_ms"] = pulled.plan_ms;
  out["sim_ok"] = world.status().ok;
  out["robot_s"] = world.time();
  out["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  if (!world.status().ok) {
    out["failure"] = "sim_unstable: " + world.status().message;
    return out;
  }
  // Labelled whenever the tool was in the hand when the action ran: an action the robot could
  // not perform with this tool in this pose (unreachable, lost tool) moved the ball (about)
  // nothing, and that is what the tool affords there.
  out["labelled"] = true;
  out["failure"] = pulled.status == control::PullStatus::kPulled
                       ? ""
                       : std::string("action_") + control::ToString(pulled.status) + ": " + pulled.reason;
  return out;
}

void PrintEvaluation(const nlohmann::json& evaluation) {
  for (const char* key : {"leave_one_family_out", "leave_one_tool_out"}) {
    if (!evaluation.contains(key)) continue;
    const nlohmann::json& e = evaluation.at(key);
    std::printf("%s (baseline: always the training mean)\n", key);
    std::printf("  %-12s %7s %7s %12s %12s %12s %12s %8s\n", "action", "trials", "groups", "MAE model", "MAE mean",
                "RMSE model", "RMSE mean", "corr");
    auto row = [](const nlohmann::json& r) {
      auto cm = [&](const char* k) { return r.at(k).is_null() ? std::nan("") : 100 * r.at(k).get<double>(); };
      std::printf("  %-12s %7d %7d %9.2f cm %9.2f cm %9.2f cm %9.2f cm %8.2f\n", r.at("action").get<std::string>().c_str(),
                  r.at("samples").get<int>(), r.at("groups").get<int>(), cm("mae_model_m"), cm("mae_mean_m"),
                  cm("rmse_model_m"), cm("rmse_mean_m"),
                  r.at("group_correlation").is_null() ? std::nan("") : r.at("group_correlation").get<double>());
    };
    for (const nlohmann::json& r : e.at("per_action")) row(r);
    row(e.at("overall"));
  }
}

}  // namespace

void ExploreRequest::Validate() const {
  if (out_dir.empty()) ThrowInvalid("explore: --out is required");
  if (actions.empty()) ThrowInvalid("explore: no action (expected some of pull, drag-left, drag-right, push)");
  std::set<std::string> seen;
  for (const std::string& a : actions) {
    if (!control::ParseToolAction(a)) {
      ThrowInvalid("explore: unknown action '", a, "' (expected pull, drag-left, drag-right or push)");
    }
    if (!seen.insert(a).second) ThrowInvalid("explore: action '", a, "' given twice");
  }
  if (orientations_deg.empty()) ThrowInvalid("explore: no orientation");
  std::set<double> rolls;
  for (double r : orientations_deg) {
    if (!(r >= 0 && r < 360)) ThrowInvalid("explore: orientation ", r, " deg (expected in [0, 360))");
    if (!rolls.insert(r).second) ThrowInvalid("explore: orientation ", r, " deg given twice");
  }
  if (balls < 1) ThrowInvalid("explore: balls = ", balls, " (expected >= 1)");
  if (jobs < 1) ThrowInvalid("explore: jobs = ", jobs, " (expected >= 1)");
  if (limit < 0) ThrowInvalid("explore: limit = ", limit, " (expected >= 0)");
  if (!(case_timeout_s > 0)) ThrowInvalid("explore: case_timeout_s = ", case_timeout_s, " (expected > 0)");
}

nlohmann::json TrainFromExploration(const std::filesystem::path& results_jsonl, const std::filesystem::path& out_dir,
                                    const nlohmann::json& info, const std::vector<std::string>& tools_wanted,
                                    const std::vector<std::string>& actions_wanted) {
  auto wanted = [](const std::vector<std::string>& list, const std::string& name) {
    return list.empty() || std::find(list.begin(), list.end(), name) != list.end();
  };
  std::vector<AffordanceSample> samples;
  for (AffordanceSample& s : ReadAffordanceSamples(results_jsonl)) {
    if (wanted(tools_wanted, s.tool) && wanted(actions_wanted, s.action)) samples.push_back(std::move(s));
  }
  // An action with a single labelled trial cannot be trained (nor evaluated): left out, said so.
  std::map<std::string, int> per_action;
  for (const AffordanceSample& s : samples) ++per_action[s.action];
  std::erase_if(samples, [&](const AffordanceSample& s) {
    if (per_action[s.action] >= 2) return false;
    spdlog::warn("explore: action '{}' has {} labelled trial: left out of the model", s.action, per_action[s.action]);
    return true;
  });
  if (samples.size() < 2) {
    ThrowInvalid("explore: ", results_jsonl.string(), " holds ", samples.size(),
                 " usable labelled trial(s) of the selected tools and actions (an action needs at least 2)");
  }
  AffordanceModel model = AffordanceModel::Train(samples);
  model.info = info;
  std::set<std::string> tools, families;
  for (const AffordanceSample& s : samples) {
    tools.insert(s.tool);
    families.insert(s.family);
  }
  model.info["labelled_trials"] = samples.size();
  model.info["tools"] = std::vector<std::string>(tools.begin(), tools.end());
  model.Save(out_dir / "affordance_model.json");
  nlohmann::json evaluation;
  evaluation["labelled_trials"] = samples.size();
  if (families.size() >= 2) {
    evaluation["leave_one_family_out"] = HeldOutJson(EvaluateHeldOut(samples, HoldOut::kFamily));
  }
  if (tools.size() >= 2) evaluation["leave_one_tool_out"] = HeldOutJson(EvaluateHeldOut(samples, HoldOut::kTool));
  WriteJson(out_dir / "evaluation.json", evaluation);
  PrintEvaluation(evaluation);
  return evaluation;
}

int RunExplore(const ExploreRequest& request) {
  request.Validate();
  SceneRequest scene_request;
  scene_request.seed = request.seed;
  // The library's analyses as an episode's perception makes them: its shape options, cache and
  // recorded segmentation.
  const perception::AnalyzerOptions analyzer = DefaultAnalyzerOptions();
  ExploreContext ctx{LoadScene(scene_request), {}, {}, analyzer.shape,
                     perception::ShapeCache(analyzer.shape_cache_dir,
                                            perception::ReadShapeSegmentations(analyzer.shape_segmentations))};
  std::regex pattern;
  try {
    pattern = std::regex(request.tools.empty() ? std::string(".*") : request.tools);
  } catch (const std::regex_error& e) {
    ThrowInvalid("explore: --tools '", request.tools, "' is not a valid regular expression (", e.what(), ")");
  }
  std::vector<std::string> tools;
  for (const auto& m : ctx.base.library) {
    ctx.names.push_back(m.name);
    ctx.models[m.name] = &m;
    if (std::regex_search(m.name, pattern)) tools.push_back(m.name);
  }
  std::sort(tools.begin(), tools.end());
  if (tools.empty()) ThrowInvalid("explore: --tools '", request.tools, "' matches no library tool");

  std::vector<SweepCase> cases;
  for (const std::string& tool : tools) {
    for (const std::string& action : request.actions) {
      for (double roll : request.orientations_deg) {
        for (int b = 0; b < request.balls; ++b) {
          SweepCase c;
          c.index = static_cast<int>(cases.size());
          c.id = fmt::format("{}/{}/r{:g}/b{}", tool, action, roll, b);
          c.params = {{"tool", tool},
                      {"action", action},
                      {"roll_deg", roll},
                      {"ball", b},
                      {"seed", DeriveSeed(request.seed, "explore/" + c.id)}};
          cases.push_back(std::move(c));
        }
      }
    }
  }
  nlohmann::json info = {{"command", "explore"},
                         {"seed", request.seed},
                         {"tools", request.tools},
                         {"actions", request.actions},
                         {"orientations_deg", request.orientations_deg},
                         {"balls", request.balls},
                         {"trials", cases.size()}};
  SweepOptions sweep;
  sweep.out_dir = request.out_dir;
  sweep.protocol = "explore";
  sweep.jobs = request.jobs;
  sweep.resume = request.resume;
  sweep.limit = request.limit;
  sweep.isolate = request.isolate;
  sweep.case_timeout_s = request.case_timeout_s;
  sweep.run_info = info;
  if (request.train_only) {
    TrainFromExploration(request.out_dir / "results.jsonl", request.out_dir, info, tools, request.actions);
    return 0;
  }
  const auto start = std::chrono::steady_clock::now();
  const std::vector<SweepLine> lines = RunSweep(
      sweep, cases, [&](const SweepCase& c) { return RunTrial(ctx, c); },
      [&](const std::vector<SweepCase>& to_run) {
        // Shape analyses once, in the parent: the children inherit them.
        std::set<std::string> needed;
        for (const SweepCase& c : to_run) needed.insert(c.params.at("tool").get<std::string>());
        for (const std::string& t : needed) ctx.shapes.Get(*ctx.models.at(t), ctx.shape_options);
      });
  const double wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  // Summary: per tool family and action, the mean displacement and the failure reasons.
  struct Tally {
    int trials = 0, labelled = 0, crashed = 0;
    double along = 0.0, wall = 0.0;
  };
  std::map<std::string, Tally> per_family_action;
  std::map<std::string, int> reasons;
  Tally total;
  const std::set<std::string> selected(tools.begin(), tools.end());
  for (const SweepLine& line : lines) {
    // A resumed folder may hold trials of other tools or actions (an earlier, wider run).
    const std::string id = line.value("id", "");
    const std::string line_tool = id.substr(0, id.find('/'));
    const std::string rest = id.substr(id.find('/') + 1);
    const std::string line_action = rest.substr(0, rest.find('/'));
    if (selected.count(line_tool) == 0 ||
        std::find(request.actions.begin(), request.actions.end(), line_action) == request.actions.end()) {
      continue;
    }
    ++total.trials;
    if (!line.value("ok", false)) {
      ++total.crashed;
      ++reasons["crashed"];
      continue;
    }
    const nlohmann::json& r = line.at("result");
    Tally& t = per_family_action[r.at("family").get<std::string>() + "/" + r.at("action").get<std::string>()];
    ++t.trials;
    total.wall += line.value("wall_s", 0.0);
    const std::string failure = r.value("failure", "");
    if (!failure.empty()) ++reasons[failure.substr(0, failure.find(':'))];
    if (r.value("labelled", false)) {
      ++t.labelled;
      ++total.labelled;
      t.along += r.at("displacement_along_m").get<double>();
    }
  }
  nlohmann::json summary = info;
  summary["trials_recorded"] = total.trials;
  summary["labelled"] = total.labelled;
  summary["crashed"] = total.crashed;
  summary["mean_trial_wall_s"] = total.trials > total.crashed ? total.wall / (total.trials - total.crashed) : 0.0;
  summary["run_wall_s"] = wall_s;
  summary["failure_reasons"] = reasons;
  for (const auto& [key, t] : per_family_action) {
    summary["per_family_action"][key] = {{"trials", t.trials},
                                         {"labelled", t.labelled},
                                         {"mean_displacement_along_m", t.labelled > 0 ? t.along / t.labelled : 0.0}};
  }
  const nlohmann::json evaluation =
      TrainFromExploration(request.out_dir / "results.jsonl", request.out_dir, info, tools, request.actions);
  summary["evaluation"] = evaluation;
  WriteJson(request.out_dir / "summary.json", summary);
  spdlog::info("explore: {} trials ({} labelled, {} crashed), {:.1f} s per trial of wall time; model in {}",
               total.trials, total.labelled, total.crashed, summary["mean_trial_wall_s"].get<double>(),
               (request.out_dir / "affordance_model.json").string());
  return 0;
}

}  // namespace toolbench::app
