#include "app/bench_episodes.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <sstream>
#include <string>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "app/bench_pull.h"
#include "app/episode.h"
#include "common/check.h"
#include "common/paths.h"
#include "common/rng.h"

namespace toolbench::app {

namespace {

// The choice in hindsight (BenchRequest::hindsight): every tool of the episode's rack pulls the
// episode's ball from its ground-truth handle (RunPullCase: that tool alone in its cell, the look
// at it in the hand on), then JudgeChoiceInHindsight; sets truth.hindsight and, when judged,
// truth.choice_correct.
void ScoreChoiceInHindsight(const SceneRequest& scene_request, nlohmann::json* result) {
  nlohmann::json& truth = (*result)["truth"];
  const LoadedScene scene = LoadScene(scene_request);
  const std::vector<double> ball = truth.at("ball_start_R").get<std::vector<double>>();
  PullCaseOptions options;
  options.put_down_and_grasp_ball = false;
  options.ball_x_range = {ball.at(0), ball.at(0)};
  options.ball_y_range = {ball.at(1), ball.at(1)};
  nlohmann::json pulls = nlohmann::json::array();
  for (const nlohmann::json& tool : truth.at("tools")) {
    options.cell = tool.at("cell").get<std::string>();
    const std::string name = tool.at("name").get<std::string>();
    nlohmann::json entry = {{"tool", name}, {"cell", options.cell}};
    try {
      const PullCaseResult r = RunPullCase(scene, name, DeriveSeed(scene_request.seed, "hindsight/" + name), options);
      entry["ball_in_reach"] = r.ball_in_reach;
      entry["displacement_m"] = r.displacement_m;
      entry["reason"] = r.reason;
    } catch (const std::exception& e) {  // recorded: the episode's own result must not be lost
      entry["ball_in_reach"] = false;
      entry["displacement_m"] = 0.0;
      entry["reason"] = std::string("error: ") + e.what();
    }
    pulls.push_back(entry);
  }
  const nlohmann::json judged = JudgeChoiceInHindsight(pulls, result->value("chosen_tool", std::string()));
  if (judged.contains("correct")) truth["choice_correct"] = judged["correct"];
  truth["hindsight"] = judged;
}

// The first stage of a result.json named `name`, or an empty object when it did not run.
nlohmann::json StageOf(const nlohmann::json& result, const std::string& name) {
  for (const auto& s : result.value("stages", nlohmann::json::array())) {
    if (s.value("name", "") == name) return s;
  }
  return nlohmann::json::object();
}

// A stage's details field `key`, or `fallback` when the stage or the field is missing.
template <typename T>
T DetailOf(const nlohmann::json& stage, const char* key, T fallback) {
  return stage.value("details", nlohmann::json::object()).value(key, fallback);
}

}  // namespace

std::string HelpReason(const nlohmann::json& result) {
  const nlohmann::json grasp = StageOf(result, "grasp_tool");
  if (grasp.value("outcome", "") == "handed_over") {
    return DetailOf(grasp, "grasp_planned", true) ? "hand-over: the grasp failed" : "hand-over: the handle out of reach";
  }
  if (!StageOf(result, "re_grip").empty()) return "re-grip: the look at the tool in the hand found none";
  for (const auto& s : result.value("stages", nlohmann::json::array())) {
    if (!DetailOf(s, "regrip_after", std::string()).empty()) return "re-grip: no plan of the action from the robot's own grip";
  }
  return "other";
}

nlohmann::json JudgeChoiceInHindsight(const nlohmann::json& pulls, const std::string& chosen_tool) {
  if (!pulls.is_array() || pulls.empty()) ThrowInvalid("JudgeChoiceInHindsight: no pulls to judge against");
  for (const nlohmann::json& p : pulls) {
    if (!p.contains("tool") || !p.contains("ball_in_reach") || !p.contains("displacement_m") ||
        !p["ball_in_reach"].is_boolean() || !p["displacement_m"].is_number()) {
      ThrowInvalid("JudgeChoiceInHindsight: pull ", p.dump(), " lacks tool, ball_in_reach or displacement_m");
    }
  }
  // The best: in reach first, then the longest displacement (a ball flung past the robot or off
  // the table moved far but is not a better outcome, hence only the reach decides "correct").
  size_t best = 0;
  int in_reach = 0;
  for (size_t i = 0; i < pulls.size(); ++i) {
    const bool reach = pulls[i]["ball_in_reach"].get<bool>();
    in_reach += reach;
    const bool best_reach = pulls[best]["ball_in_reach"].get<bool>();
    if (reach != best_reach ? reach
                            : pulls[i]["displacement_m"].get<double>() > pulls[best]["displacement_m"].get<double>()) {
      best = i;
    }
  }
  const double n = static_cast<double>(pulls.size());
  nlohmann::json judged = {{"pulls", pulls}, {"best_tool", pulls[best]["tool"]}, {"in_reach", in_reach}};
  if (in_reach > 0) {
    bool correct = false;
    for (const nlohmann::json& p : pulls) correct = correct || (p["ball_in_reach"].get<bool>() && p["tool"] == chosen_tool);
    judged["correct"] = correct;
    judged["chance"] = in_reach / n;
  }
  return judged;
}

int RunRandomEpisodesBench(const BenchRequest& request) {
  const int episodes = request.episodes > 0 ? request.episodes : 50;
  std::vector<SweepCase> cases;
  for (int i = 0; i < episodes; ++i) {
    SweepCase c;
    c.index = i;
    c.id = "episode/" + std::to_string(i);
    c.params = {{"scene_seed", DeriveSeed(request.seed, "random/" + std::to_string(i))}};
    cases.push_back(c);
  }
  // What every episode shares (library, perception's models, affordance model) is loaded once,
  // here, before the children fork: each starts with it (EpisodeResources).
  std::shared_ptr<const EpisodeResources> resources;
  auto prepare = [&](const std::vector<SweepCase>&) {
    EpisodeRequest any;
    any.scene = BenchScene(request, 0);
    resources = std::make_shared<const EpisodeResources>(LoadEpisodeResources(any));
    spdlog::info("random: library and models loaded in {:.2f} s", resources->load_ms / 1000);
  };
  auto run_case = [&](const SweepCase& c) {
    EpisodeRequest episode;
    episode.scene = BenchScene(request, c.params["scene_seed"].get<std::uint64_t>());
    episode.resources = resources;
    episode.quiet = true;
    episode.best_tool_only = request.best_tool_only;
    episode.check_action_before_grasp = request.check_action_before_grasp;
    episode.look_again_after_failed_grasp = request.look_again_after_failed_grasp;
    episode.frames = request.frames;
    episode.out_dir = request.out_dir / "episodes" / std::to_string(c.index);
    nlohmann::json result = EpisodeJson(RunEpisode(episode));
    if (request.hindsight && !result.value("ball_reachable_at_start", true) &&
        !result.value("chosen_tool", std::string()).empty()) {
      ScoreChoiceInHindsight(episode.scene, &result);
    }
    return result;
  };
  nlohmann::json info;
  info["episodes"] = episodes;
  info["hindsight"] = request.hindsight;
  info["best_tool_only"] = request.best_tool_only;
  info["check_action_before_grasp"] = request.check_action_before_grasp;
  info["look_again_after_failed_grasp"] = request.look_again_after_failed_grasp;
  ReportRandomEpisodes(request, RunSweep(SweepOptionsFor(request, "random", info), cases, run_case, prepare));
  return 0;
}

void ReportRandomEpisodes(const BenchRequest& request, const std::vector<SweepLine>& lines) {
  std::map<std::string, Tally> rates;
  std::map<std::string, std::vector<double>> stage_ms;
  std::map<std::string, std::vector<double>> stage_robot_s;
  std::map<std::string, std::vector<double>> stage_physics_ms;
  std::vector<std::string> stage_order;  // as the episodes ran them (first seen first)
  std::map<std::string, int> failures;
  std::vector<double> wall_s, cpu_s, robot_s, physics_s, displacement;
  std::vector<double> drift_deg, drift_m;  // the tool's turn in the grip where the pull's drag starts
  std::vector<double> chance;  // per scored choice: 1 / tools on the rack (a random pick's agreement)
  std::map<std::string, int> help_reasons;  // assisted episodes by HelpReason
  int crashed = 0;
  for (const SweepLine& line : lines) {
    if (!line.value("ok", false)) {
      ++crashed;
      ++failures["crashed: " + line.value("error", std::string()).substr(0, 60)];
      continue;
    }
    const nlohmann::json& r = line["result"];
    const bool needed_tool = !r.value("ball_reachable_at_start", false);
    auto count = [&](const std::string& name, bool ok) { rates[name].Add(ok); };
    if (needed_tool) {
      // choice_made: the choose_tool stage picked a tool; choice_correct when the episode scored
      // its choice against ground truth (truth.choice_correct).
      count("choice_made", StageOf(r, "choose_tool").value("ok", false));
      if (r["truth"].contains("choice_correct")) {
        count("choice_correct", r["truth"]["choice_correct"].get<bool>());
        chance.push_back(r["truth"]["hindsight"].value("chance", std::nan("")));
      }
      count("grasp_success", r.value("grasp_success", false));
      // Over the episodes whose tool's handle was within reach (a grasp planned), as grasp-gt
      // rates the cells: a handle out of reach is the hand-over's case, not a failed grasp.
      if (DetailOf(StageOf(r, "grasp_tool"), "grasp_planned", false)) {
        count("grasp_success_within_reach", r.value("grasp_success", false));
      }
      // Over the episodes whose grasp failed once it moved, and that looked at the rack again
      // (EpisodeRequest::look_again_after_failed_grasp).
      if (DetailOf(StageOf(r, "grasp_tool"), "looks_again", 0) > 0) {
        count("grasp_success_after_look_again", r.value("grasp_success", false));
      }
      if (r["truth"].contains("chosen_tool_perception")) {
        // Ground truth: the tool the robot went for was perceived perfectly (Table 5.3's score 1).
        count("chosen_tool_perceived", r["truth"]["chosen_tool_perception"].value("score", 0.0) >= 1.0);
      }
      count("pull_success", r.value("pull_success", false));
      count("assisted", r.value("assisted", false));
      if (r.value("assisted", false)) ++help_reasons[HelpReason(r)];
      displacement.push_back(r.value("achieved_displacement_m", 0.0));
    }
    count("ball_grasp_success", r.value("ball_grasp_success", false));
    count("completed", r.value("failure", std::string()).empty());
    wall_s.push_back(r.value("wall_s", 0.0));
    if (r.contains("cpu_s")) cpu_s.push_back(r["cpu_s"].get<double>());  // since session 44
    robot_s.push_back(r.value("robot_s", 0.0));
    double physics_ms = 0.0;
    for (const auto& s : r["stages"]) {
      const std::string name = s["name"];
      if (!stage_ms.count(name)) stage_order.push_back(name);
      stage_ms[name].push_back(s["wall_ms"].get<double>());
      stage_robot_s[name].push_back(s.value("robot_s", 0.0));
      stage_physics_ms[name].push_back(s.value("physics_ms", 0.0));
      physics_ms += s.value("physics_ms", 0.0);
      if (name == "pull" && s.contains("details") && s["details"].contains("at_start_error_deg_truth")) {
        drift_deg.push_back(s["details"]["at_start_error_deg_truth"].get<double>());
        drift_m.push_back(s["details"]["at_start_effector_error_m_truth"].get<double>());
      }
    }
    physics_s.push_back(physics_ms / 1000.0);
    const std::string failure = r.value("failure", std::string());
    if (!failure.empty()) ++failures[failure.substr(0, failure.find(':'))];
  }
  nlohmann::json summary;
  summary["protocol"] = "random";
  summary["seed"] = request.seed;
  summary["episodes"] = lines.size();
  summary["crashed"] = crashed;
  for (const auto& [name, rate] : rates) {
    const auto [lo, hi] = WilsonInterval(rate.ok, rate.n);
    summary[name] = {{"rate", rate.n > 0 ? static_cast<double>(rate.ok) / rate.n : std::nan("")},
                     {"successes", rate.ok},
                     {"n", rate.n},
                     {"ci95", {lo, hi}}};
  }
  if (!chance.empty()) {
    double sum = 0.0;
    for (double c : chance) sum += c;
    summary["choice_correct_by_chance"] = sum / static_cast<double>(chance.size());
  }
  summary["achieved_displacement_m_median"] = Percentile(displacement, 50);
  summary["wall_s_median"] = Percentile(wall_s, 50);
  summary["wall_s_p90"] = Percentile(wall_s, 90);
  if (!cpu_s.empty()) summary["cpu_s_median"] = Percentile(cpu_s, 50);
  summary["robot_s_median"] = Percentile(robot_s, 50);
  summary["physics_s_median"] = Percentile(physics_s, 50);  // wall time inside mj_step
  // Ground truth, for scoring: how far the tool had turned in the grip since the inspection when
  // the pull's drag started (rotation; the effector's displacement), over the executed pulls.
  summary["grip_drift_at_drag_start"] = {{"deg_median", Percentile(drift_deg, 50)},
                                         {"deg_p90", Percentile(drift_deg, 90)},
                                         {"effector_m_median", Percentile(drift_m, 50)},
                                         {"n", drift_deg.size()}};
  for (const auto& [name, values] : stage_ms) {
    summary["stage_ms"][name] = {
        {"median", Percentile(values, 50)}, {"p90", Percentile(values, 90)}, {"n", values.size()}};
    summary["stage_robot_s_median"][name] = Percentile(stage_robot_s[name], 50);
    summary["stage_physics_ms_median"][name] = Percentile(stage_physics_ms[name], 50);
  }
  summary["failures"] = failures;
  summary["help_reasons"] = help_reasons;
  WriteJson(request.out_dir / "summary.json", summary);

  std::ostringstream md;
  md << "# Random episodes\n\nSeed " << request.seed << ", " << lines.size() << " episodes (" << crashed
     << " crashed).\n\n| rate | value | 95 % interval | n |\n|---|---|---|---|\n";
  for (const auto& [name, rate] : rates) {
    const auto [lo, hi] = WilsonInterval(rate.ok, rate.n);
    md << fmt::format("| {} | {:.0f} % | {:.0f}–{:.0f} % | {} |\n", name, rate.n ? 100.0 * rate.ok / rate.n : NAN,
                      100 * lo, 100 * hi, rate.n);
  }
  if (summary.contains("choice_correct_by_chance")) {
    md << fmt::format("\nchoice_correct: agreement with the best tool in hindsight (every tool of the rack pulled "
                      "from its ground-truth handle): the chosen tool brought the ball into reach there, over the "
                      "episodes where some tool did; a random pick would be right {:.0f} % of the time.\n",
                      100 * summary["choice_correct_by_chance"].get<double>());
  }
  md << "\n| stage | episodes | wall median ms | wall p90 ms | of it physics, median ms | robot (simulated) "
        "median s |\n|---|---|---|---|---|---|\n";
  for (const std::string& name : stage_order) {
    const std::vector<double>& values = stage_ms[name];
    md << fmt::format("| {} | {} | {:.0f} | {:.0f} | {:.0f} | {:.1f} |\n", name, values.size(), Percentile(values, 50),
                      Percentile(values, 90), Percentile(stage_physics_ms[name], 50),
                      Percentile(stage_robot_s[name], 50));
  }
  md << fmt::format("\nWall time per episode: median {:.1f} s, p90 {:.1f} s; of it physics (mj_step) {:.1f} s; "
                    "robot (simulated) time {:.1f} s{}.\n",
                    Percentile(wall_s, 50), Percentile(wall_s, 90), Percentile(physics_s, 50), Percentile(robot_s, 50),
                    cpu_s.empty() ? std::string() : fmt::format("; CPU time (every thread) {:.1f} s", Percentile(cpu_s, 50)));
  if (!drift_deg.empty()) {
    md << fmt::format("\nThe tool's turn in the grip since the inspection where the drag started (ground truth, "
                      "{} pulls): median {:.1f} deg (p90 {:.1f}), the effector {:.1f} mm off the plan's.\n",
                      drift_deg.size(), Percentile(drift_deg, 50), Percentile(drift_deg, 90),
                      1000 * Percentile(drift_m, 50));
  }
  if (!help_reasons.empty()) {
    md << "\n| why the robot was helped | episodes |\n|---|---|\n";
    for (const auto& [reason, n] : help_reasons) md << "| " << reason << " | " << n << " |\n";
  }
  if (!failures.empty()) {
    md << "\n| first failure | episodes |\n|---|---|\n";
    for (const auto& [name, n] : failures) md << "| " << name << " | " << n << " |\n";
  }
  // The plots: success rates with their intervals, and how long each stage takes.
  if (!rates.empty()) {
    BarChart chart;
    chart.title = fmt::format("random episodes: success rates (95 % Wilson intervals), {} episodes", lines.size());
    chart.x_label = "outcome (grasp, pull, assisted, choice: episodes that needed a tool)";
    chart.y_label = "rate [%]";
    chart.y_max = 112;
    chart.value_labels = true;
    std::vector<Tally> tallies;
    for (const auto& [name, rate] : rates) {
      chart.categories.push_back(name);
      tallies.push_back(rate);
    }
    chart.series.push_back(RateSeries("", tallies));
    WriteBarChartPng(chart, request.out_dir / "rates.png");
    md << "\n" << MarkdownImage("success rates with 95 % intervals", "rates.png");
  }
  if (!stage_ms.empty()) {
    std::vector<Histogram> panels;
    for (const std::string& name : stage_order) {
      const std::vector<double>& values = stage_ms[name];
      Histogram h;
      h.title = name;
      h.x_label = "wall time [s]";
      h.y_label = "episodes";
      for (double ms : values) h.values.push_back(ms / 1000);
      h.bins = std::clamp(static_cast<int>(values.size()) / 2, 5, 20);
      panels.push_back(h);
    }
    Histogram whole;
    whole.title = "whole episode";
    whole.x_label = "wall time [s]";
    whole.y_label = "episodes";
    whole.values = wall_s;
    whole.bins = std::clamp(static_cast<int>(wall_s.size()) / 2, 5, 20);
    panels.push_back(whole);
    WriteHistogramsPng(panels, request.out_dir / "stage_times.png", 3);
    md << "\n" << MarkdownImage("stage wall-time histograms", "stage_times.png");
  }
  WriteTextFile(request.out_dir / "summary.md", md.str());
}

}  // namespace toolbench::app
