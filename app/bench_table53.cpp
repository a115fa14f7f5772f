#include "app/bench_table53.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "app/capture.h"
#include "app/episode.h"
#include "app/perceive.h"
#include "app/scene_setup.h"
#include "app/scoring.h"
#include "app/sweep.h"
#include "common/check.h"
#include "common/paths.h"
#include "common/rng.h"
#include "perception/analysis.h"
#include "sim/renderer.h"
#include "sim/scene_composer.h"
#include "sim/world.h"

namespace toolbench::app {
namespace {

constexpr std::array<const char*, 7> kThesisCells = {"pos1", "pos2", "pos3", "rot0", "rot1", "rot2", "rot3"};

/// The thesis cell with the same tool pose as `cell` ("" when none): the 7 cells themselves;
/// of the extended ones pos<i>_rot0 is pos<i> and pos2_rot<j> is rot<j>.
std::string ThesisCounterpart(const std::string& cell) {
  if (cell.size() == 4) return cell;
  if (cell == "pos2_rot0") return "rot0";
  if (cell.size() == 9 && cell.substr(5) == "rot0") return cell.substr(0, 4);
  if (cell.size() == 9 && cell.substr(0, 4) == "pos2") return cell.substr(5);
  return "";
}

/// The published per-cell score of the thesis (mean over its 29 tools).
double PublishedCellMean(const std::string& thesis_cell);

/// Thesis Table 5.3 (simulation, scored by eye): per tool, pos1..rot3. Tools
/// marked * in the thesis (hoe6, hok6, lstick) were not rotated and scored 0
/// there; they are kept as published.
struct ThesisRow {
  const char* tool;
  const char* family;  // our family name
  std::array<double, 7> cells;
};
constexpr ThesisRow kThesisTable[] = {
    {"hoe", "hoe", {0.5, 0.5, 1.0, 1.0, 1.0, 1.0, 0.0}},
    {"hoe1", "hoe", {1.0, 1.0, 0.5, 1.0, 0.5, 1.0, 1.0}},
    {"hoe2", "hoe", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"hoe3", "hoe", {1.0, 1.0, 0.0, 0.0, 0.5, 0.5, 1.0}},
    {"hoe4", "hoe", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"hoe5", "hoe", {1.0, 0.0, 0.5, 1.0, 1.0, 0.5, 1.0}},
    {"hoe6*", "hoe", {0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0}},
    {"hoe7", "hoe", {1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0}},
    {"hok1", "hook", {1.0, 0.5, 0.0, 1.0, 1.0, 1.0, 1.0}},
    {"hok2", "hook", {1.0, 1.0, 1.0, 0.5, 1.0, 0.5, 1.0}},
    {"hok3", "hook", {1.0, 1.0, 0.5, 0.5, 1.0, 0.5, 1.0}},
    {"hok4", "hook", {1.0, 1.0, 0.0, 0.5, 1.0, 0.5, 0.5}},
    {"hok5", "hook", {0.5, 0.5, 1.0, 1.0, 1.0, 0.5, 1.0}},
    {"hok6*", "hook", {0.0, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0}},
    {"hok7", "hook", {1.0, 0.5, 0.0, 0.0, 1.0, 0.5, 1.0}},
    {"lstick*", "lstick", {0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0}},
    {"lstick1", "lstick", {0.5, 1.0, 1.0, 1.0, 1.0, 0.5, 1.0}},
    {"rak", "rake", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"rak1", "rake", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"rak2", "rake", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"rak3", "rake", {1.0, 1.0, 1.0, 1.0, 0.5, 1.0, 1.0}},
    {"rak4", "rake", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"rak5", "rake", {1.0, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"stick", "stick", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"stick1", "stick", {1.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.5}},
    {"stick2", "stick", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"stick3", "stick", {1.0, 1.0, 1.0, 0.0, 1.0, 0.0, 1.0}},
    {"stick4", "stick", {1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0}},
    {"stick5", "stick", {1.0, 1.0, 0.0, 0.5, 0.0, 1.0, 1.0}},
};

/// One configuration's result on one case.
struct MethodResult {
  CellScore score;
  std::string model;  // recognised model ("" when none)
  double confidence = 0.0;
  int segments = 0;
  perception::StageTimes times;
  std::string status;  // ToString(AnalysisStatus) of the chosen analysis, or
                       // "no_segment"
  std::string reason;
};

/// Picks, among the frame's analysed tools, the one that is the true tool (the
/// fitted tool centre nearest the true one: association by position, not by
/// score) and scores it.
MethodResult Evaluate(const perception::FrameAnalysis& frame, const std::vector<toollib::ToolModel>& library,
                      const toollib::ToolModel& truth, const Eigen::Isometry3d& X_RT_true) {
  MethodResult out;
  out.segments = static_cast<int>(frame.tools.size());
  auto find = [&](const std::string& name) -> const toollib::ToolModel* {
    for (const auto& m : library) {
      if (m.name == name) return &m;
    }
    return nullptr;
  };
  const Eigen::Vector3d mid_true = X_RT_true * Eigen::Vector3d(0, 0, truth.total_length / 2);
  int best = -1;
  double best_distance = 1e9;
  for (size_t i = 0; i < frame.tools.size(); ++i) {
    const perception::ToolAnalysis& a = frame.tools[i];
    if (a.status != perception::AnalysisStatus::kOk) continue;
    const toollib::ToolModel* m = find(a.model);
    const double length = m != nullptr ? m->total_length : 0.0;
    const double d = (a.X_RT * Eigen::Vector3d(0, 0, length / 2) - mid_true).norm();
    if (d < best_distance) {
      best_distance = d;
      best = static_cast<int>(i);
    }
  }
  if (best < 0) {
    out.status = frame.tools.empty() ? "no_segment" : perception::ToString(frame.tools.front().status);
    out.reason = frame.tools.empty() ? "no tool segmented" : frame.tools.front().reason;
    out.score.verdict = "not_found";
    out.score.handle_error_m = std::nan("");
    for (const auto& t : frame.times) out.times.segmentation_ms += t.segmentation_ms;
    return out;
  }
  const perception::ToolAnalysis& a = frame.tools[static_cast<size_t>(best)];
  const toollib::ToolModel* fitted = find(a.model);
  out.score = ScoreCell(a, truth, X_RT_true, fitted != nullptr ? fitted->family : "");
  out.model = a.model;
  out.confidence = a.confidence;
  out.times = frame.times[static_cast<size_t>(best)];
  out.status = perception::ToString(a.status);
  return out;
}

nlohmann::json TimesJson(const perception::StageTimes& t) {
  return {{"segmentation", t.segmentation_ms}, {"cloud", t.cloud_ms}, {"classification", t.classification_ms},
          {"recognition", t.recognition_ms},   {"shape", t.shape_ms}, {"total", t.total_ms}};
}

nlohmann::json MethodJson(const MethodResult& r) {
  return {{"score", r.score.score},
          {"verdict", r.score.verdict},
          {"status", r.status},
          {"reason", r.reason},
          {"model", r.model},
          {"confidence", r.confidence},
          {"recognised", r.score.recognised},
          {"family_recognised", r.score.family_recognised},
          {"segments", r.segments},
          {"handle_error_m",
           std::isfinite(r.score.handle_error_m) ? nlohmann::json(r.score.handle_error_m) : nlohmann::json()},
          {"axis_error_deg", r.score.axis_error_deg},
          {"effector_error_deg", r.score.effector_error_deg},
          {"ms", TimesJson(r.times)}};
}

/// Aggregates of one configuration over the cases run.
struct Aggregate {
  std::vector<double> scores, handle_errors;
  int recognised = 0, family_recognised = 0;
  std::map<std::string, std::vector<double>> stage_ms;
  std::map<std::string, std::map<std::string, std::vector<double>>> cell;  // tool -> cell -> scores (repeats)
  std::map<std::string, int> verdicts;

  /// Adds one configuration's entry of a results line (see MethodJson).
  void Add(const std::string& tool, const std::string& cell_name, const nlohmann::json& r) {
    const double score = r.at("score").get<double>();
    scores.push_back(score);
    // A tool not found has no handle error; it counts as infinitely wrong in the percentiles.
    handle_errors.push_back(r.at("handle_error_m").is_number() ? r["handle_error_m"].get<double>() : 1e9);
    recognised += r.at("recognised").get<bool>() ? 1 : 0;
    family_recognised += r.at("family_recognised").get<bool>() ? 1 : 0;
    for (const auto& [name, ms] : r.at("ms").items()) stage_ms[name].push_back(ms.get<double>());
    cell[tool][cell_name].push_back(score);
    ++verdicts[r.at("verdict").get<std::string>()];
  }

  double Mean() const {
    double s = 0;
    for (double v : scores) s += v;
    return scores.empty() ? std::nan("") : s / static_cast<double>(scores.size());
  }
  double Share(double value) const {
    if (scores.empty()) return std::nan("");
    return static_cast<double>(std::count(scores.begin(), scores.end(), value)) / static_cast<double>(scores.size());
  }

  nlohmann::json Json() const {
    const double n = static_cast<double>(scores.size());
    nlohmann::json j;
    j["cases"] = scores.size();
    j["mean_score"] = Mean();
    j["share_perfect"] = Share(1.0);
    j["share_half"] = Share(0.5);
    j["share_zero"] = Share(0.0);
    j["recognition_accuracy"] = n > 0 ? recognised / n : std::nan("");
    j["family_recognition_accuracy"] = n > 0 ? family_recognised / n : std::nan("");
    j["handle_error_median_m"] = Percentile(handle_errors, 50);
    j["handle_error_p90_m"] = Percentile(handle_errors, 90);
    for (const auto& [name, values] : stage_ms) j["per_stage_ms_median"][name] = Percentile(values, 50);
    for (const auto& [name, count] : verdicts) j["verdicts"][name] = count;
    return j;
  }
};

std::string Score(double v) { return std::isnan(v) ? "–" : fmt::format("{:.2f}", v); }

double Mean(const std::vector<double>& v) {
  double sum = 0;
  for (double x : v) sum += x;
  return v.empty() ? std::nan("") : sum / static_cast<double>(v.size());
}

/// The per-tool table in the thesis's layout (a column per cell, the mean of repeats), with a
/// mean row.
std::string ToolTable(const Aggregate& a, const std::vector<std::string>& cells) {
  std::ostringstream md;
  md << "| tool name";
  for (const std::string& c : cells) md << " | " << c;
  md << " | overall |\n|---";
  for (size_t i = 0; i <= cells.size(); ++i) md << "|---";
  md << "|\n";
  std::map<std::string, std::vector<double>> per_cell;
  for (const auto& [tool, by_cell] : a.cell) {
    md << "| " << tool;
    std::vector<double> all;
    for (const std::string& c : cells) {
      const auto it = by_cell.find(c);
      if (it == by_cell.end()) {
        md << " | –";
        continue;
      }
      md << " | " << Score(Mean(it->second));
      all.insert(all.end(), it->second.begin(), it->second.end());
      per_cell[c].insert(per_cell[c].end(), it->second.begin(), it->second.end());
    }
    md << " | " << Score(Mean(all)) << " |\n";
  }
  md << "| **mean**";
  for (const std::string& c : cells) md << " | **" << Score(Mean(per_cell[c])) << "**";
  md << " | **" << Score(a.Mean()) << "** |\n";
  return md.str();
}

/// Mean score per cell over the tools.
std::map<std::string, double> CellMeans(const Aggregate& a) {
  std::map<std::string, std::vector<double>> per_cell;
  for (const auto& [tool, by_cell] : a.cell) {
    for (const auto& [c, v] : by_cell) per_cell[c].insert(per_cell[c].end(), v.begin(), v.end());
  }
  std::map<std::string, double> out;
  for (const auto& [c, v] : per_cell) out[c] = Mean(v);
  return out;
}

double PublishedCellMean(const std::string& thesis_cell) {
  for (size_t k = 0; k < kThesisCells.size(); ++k) {
    if (thesis_cell != kThesisCells[k]) continue;
    double sum = 0;
    for (const ThesisRow& row : kThesisTable) sum += row.cells[k];
    return sum / static_cast<double>(std::size(kThesisTable));
  }
  return std::nan("");
}

/// Mean score per family: ours, the thesis configuration on the same frames (NaN in episode
/// mode), the thesis's published Table 5.3 (NaN for families without a counterpart).
struct FamilyRow {
  double ours = std::nan("");
  double thesis_config = std::nan("");
  double published = std::nan("");
};

std::map<std::string, FamilyRow> FamilyMeans(const Aggregate& ours, const Aggregate& thesis_config,
                                             const std::vector<toollib::ToolModel>& library) {
  std::map<std::string, std::string> family_of;
  for (const auto& m : library) family_of[m.name] = m.family;
  auto family_scores = [&](const Aggregate& a) {
    std::map<std::string, std::vector<double>> scores;
    for (const auto& [tool, cells] : a.cell) {
      for (const auto& [c, v] : cells) scores[family_of[tool]].insert(scores[family_of[tool]].end(), v.begin(), v.end());
    }
    return scores;
  };
  std::map<std::string, std::vector<double>> published;
  for (const ThesisRow& row : kThesisTable) {
    published[row.family].insert(published[row.family].end(), row.cells.begin(), row.cells.end());
  }
  std::map<std::string, FamilyRow> rows;
  for (const auto& [family, v] : family_scores(ours)) rows[family].ours = Mean(v);
  for (const auto& [family, v] : family_scores(thesis_config)) rows[family].thesis_config = Mean(v);
  for (auto& [family, row] : rows) {
    if (published.count(family)) row.published = Mean(published[family]);
  }
  return rows;
}

/// Per family, with a totals row.
std::string FamilyTable(const std::map<std::string, FamilyRow>& rows, const Aggregate& ours,
                        const Aggregate& thesis_config) {
  std::ostringstream md;
  md << "| family | ours | thesis configuration (same frames) | thesis, published (Table 5.3) |\n"
     << "|---|---|---|---|\n";
  for (const auto& [family, row] : rows) {
    md << "| " << family << " | " << Score(row.ours) << " | " << Score(row.thesis_config) << " | "
       << (std::isnan(row.published) ? std::string("no counterpart") : Score(row.published)) << " |\n";
  }
  std::vector<double> published;
  for (const ThesisRow& row : kThesisTable) published.insert(published.end(), row.cells.begin(), row.cells.end());
  md << "| **all** | **" << Score(ours.Mean()) << "** | **" << Score(thesis_config.Mean()) << "** | **"
     << Score(Mean(published)) << "** |\n";
  return md.str();
}

/// The settled pose X_RT of `tool` alone in `cell` in the scene of `seed`: the same plan, MJCF
/// and settling as RunEpisode's (MuJoCo is deterministic), for scoring the episode's perception.
Eigen::Isometry3d SettledToolPose(const LoadedScene& base, const std::string& tool, const std::string& cell,
                                  std::uint64_t seed) {
  std::vector<std::string> names;
  for (const auto& t : base.library) names.push_back(t.name);
  sim::ToolPlacement placement;
  placement.tool = tool;
  placement.cell = cell;
  const sim::ScenePlan plan = sim::PlanScene(base.spec, names, seed, {placement});
  const sim::ComposedScene composed = sim::ComposeScene(base.spec, base.robot, base.library, plan);
  sim::World world(composed.mjcf, "table53 truth " + tool + " " + cell);
  world.SettleFreeBodies(base.spec.physics.settle_time);
  return composed.X_WR.inverse() * world.ground_truth().Pose(composed.tools.front().body);
}

/// The cells of a run, in protocol order: the 7 thesis cells, or the 12 extended ones when any
/// line holds one of those.
std::vector<std::string> CellsOf(const std::vector<SweepLine>& lines) {
  bool extended = false;
  for (const SweepLine& line : lines) {
    const std::string id = line.value("id", "");
    extended = extended || id.find("_rot") != std::string::npos;
  }
  std::vector<std::string> cells;
  if (extended) {
    for (std::string_view c : sim::kExtendedCellNames) cells.emplace_back(c);
  } else {
    for (const char* c : kThesisCells) cells.emplace_back(c);
  }
  return cells;
}

}  // namespace

int RunTable53Bench(const BenchRequest& request) {
  const SceneRequest library_request = BenchScene(request, request.seed);
  const LoadedScene base = LoadScene(library_request);
  std::vector<std::string> cells;
  if (request.extended) {
    for (std::string_view c : sim::kExtendedCellNames) cells.emplace_back(c);
  } else {
    for (const char* c : kThesisCells) cells.emplace_back(c);
  }
  const bool episodes = request.episodes > 0;
  std::vector<SweepCase> cases;
  for (SweepCase c : ToolCellCases(SortedToolNames(base.library), cells)) {
    for (int k = 0; k < (episodes ? request.episodes : 1); ++k) {
      SweepCase repeat = c;
      repeat.index = static_cast<int>(cases.size());
      if (episodes && request.episodes > 1) repeat.id.append(1, '/').append(std::to_string(k));
      cases.push_back(repeat);
    }
  }
  // Prepared once here; the forked case processes inherit them.
  // Both recognise with the learned classifier (the thesis had a learned recogniser too); they
  // differ in the fit and the shape analysis.
  const perception::AnalyzerOptions ours_options = DefaultAnalyzerOptions();
  perception::AnalyzerOptions thesis_options = perception::AnalyzerOptions::Thesis();
  thesis_options.classifier_file = DefaultClassifierPath();
  const perception::ToolAnalyzer ours(base.library, ours_options);
  const perception::ToolAnalyzer thesis(base.library, thesis_options);
  // Episodes: what they share (library, perception's models, affordance model), loaded once.
  std::shared_ptr<const EpisodeResources> resources;
  if (episodes) {
    EpisodeRequest any;
    any.scene = library_request;
    resources = std::make_shared<const EpisodeResources>(LoadEpisodeResources(any));
  }
  auto model_of = [&](const std::string& tool) {
    for (const auto& m : base.library) {
      if (m.name == tool) return &m;
    }
    TOOLBENCH_DEMAND(false);
    return &base.library.front();
  };

  auto perception_case = [&](const SweepCase& c) {
    const std::string tool = c.params["tool"];
    const std::string cell = c.params["cell"];
    sim::GlContext gl;
    SceneRequest scene_request = BenchScene(request, DeriveSeed(request.seed, "table53/" + c.id));
    scene_request.tools = {tool};
    scene_request.cells = {cell};
    const Capture capture = CaptureFrame(scene_request, CaptureOptions{}, gl);
    // Ground truth, for scoring only.
    const Eigen::Isometry3d X_RW = capture.scene.composed.X_WR.inverse();
    const Eigen::Isometry3d X_RT_true =
        X_RW * capture.world->ground_truth().Pose(capture.scene.composed.tools.front().body);
    const MethodResult r_ours = Evaluate(ours.Analyze(capture.frame), base.library, *model_of(tool), X_RT_true);
    const MethodResult r_thesis = Evaluate(thesis.Analyze(capture.frame), base.library, *model_of(tool), X_RT_true);
    spdlog::info("table53 {}: ours {} ({}, {:.1f} mm, {:.0f} ms) | thesis config {} ({})", c.id, r_ours.score.score,
                 r_ours.score.verdict, r_ours.score.handle_error_m * 1000, r_ours.times.total_ms, r_thesis.score.score,
                 r_thesis.score.verdict);
    return nlohmann::json{{"tool", tool},
                          {"cell", cell},
                          {"seed", scene_request.seed},
                          {"settled", capture.settled},
                          {"ours", MethodJson(r_ours)},
                          {"thesis_config", MethodJson(r_thesis)}};
  };
  // Full episode with this tool alone in this cell: the episode's own perception, scored like
  // the perception-only mode, and what became of the grasp, the pull and the ball.
  auto episode_case = [&](const SweepCase& c) {
    const std::string tool = c.params["tool"];
    const std::string cell = c.params["cell"];
    EpisodeRequest episode;
    episode.scene = BenchScene(request, DeriveSeed(request.seed, "table53/" + c.id));
    episode.scene.tools = {tool};
    episode.scene.cells = {cell};
    episode.resources = resources;
    episode.quiet = true;
    if (request.frames) episode.out_dir = request.out_dir / "episodes" / std::to_string(c.index);
    const EpisodeResult r = RunEpisode(episode);
    const Eigen::Isometry3d X_RT_true = SettledToolPose(base, tool, cell, episode.scene.seed);
    bool perceived = false;
    for (const StageRecord& stage : r.stages) perceived = perceived || stage.name == "perceive_tools";
    const MethodResult m = Evaluate(r.analysis, base.library, *model_of(tool), X_RT_true);
    spdlog::info("table53 episode {}: score {} ({}), grasp {}, pull {}, ball {}{}", c.id, m.score.score,
                 m.score.verdict, r.grasp_success, r.pull_success, r.ball_grasp_success,
                 r.failure.empty() ? "" : " — " + r.failure);
    nlohmann::json stages = nlohmann::json::object();
    for (const StageRecord& stage : r.stages) stages[stage.name] = {{"ok", stage.ok}, {"wall_ms", stage.wall_ms}};
    return nlohmann::json{{"tool", tool},
                          {"cell", cell},
                          {"seed", episode.scene.seed},
                          {"ours", MethodJson(m)},
                          {"episode",
                           {{"perceived", perceived},
                            {"ball_reachable_at_start", r.ball_reachable_at_start},
                            {"chosen_tool", r.chosen_tool},
                            {"grasp_success", r.grasp_success},
                            {"assisted", r.assisted},
                            {"pull_success", r.pull_success},
                            {"ball_grasp_success", r.ball_grasp_success},
                            {"achieved_displacement_m", r.achieved_displacement_m},
                            {"failure", r.failure},
                            {"stages", stages},
                            {"wall_s", r.wall_s},
                            {"robot_s", r.robot_s}}}};
  };
  nlohmann::json info;
  info["seed"] = request.seed;
  info["mode"] = episodes ? "episodes" : "perception";
  info["extended"] = request.extended;
  if (episodes) info["episodes_per_cell"] = request.episodes;
  info["library_preparation_ms"] = {{"ours", ours.preparation_ms()}, {"thesis_config", thesis.preparation_ms()}};
  // Shape analyses are per model and cached (on disk too): do them once here, not in every child.
  auto prepare = [&](const std::vector<SweepCase>& selected) {
    std::vector<std::string> models;
    for (const SweepCase& c : selected) models.push_back(c.params["tool"].get<std::string>());
    std::sort(models.begin(), models.end());
    models.erase(std::unique(models.begin(), models.end()), models.end());
    const auto start = std::chrono::steady_clock::now();
    ours.PrepareShapes(models);
    if (resources) resources->analyzer->PrepareShapes(models);
    spdlog::info("table53: shapes of {} model(s) ready in {:.1f} s", models.size(),
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  };
  std::function<nlohmann::json(const SweepCase&)> run_case = perception_case;
  if (episodes) run_case = episode_case;
  const std::vector<SweepLine> lines = RunSweep(SweepOptionsFor(request, "table53", info), cases, run_case, prepare);
  ReportTable53(request, lines);
  return 0;
}

void ReportTable53(const BenchRequest& request, const std::vector<SweepLine>& lines) {
  const SceneRequest library_request = BenchScene(request, request.seed);
  const std::vector<toollib::ToolModel> library = LoadScene(library_request).library;
  std::map<std::string, std::string> family_of;
  for (const auto& m : library) family_of[m.name] = m.family;
  const std::vector<std::string> cells = CellsOf(lines);
  Aggregate agg_ours, agg_thesis;
  std::vector<double> speedups;
  int failed = 0;
  bool episode_mode = false;
  // Episode mode: outcomes per cell and per family, and overall.
  std::map<std::string, std::map<std::string, Tally>> grasp_by_tool_cell;
  std::map<std::string, Tally> grasp_by_cell, grasp_by_family;
  std::map<std::string, Tally> outcomes;
  std::map<std::string, int> failures;
  for (const SweepLine& line : lines) {
    if (!line.value("ok", false)) {
      ++failed;
      ++failures["did not run: " + line.value("error", std::string()).substr(0, 60)];
      continue;
    }
    const nlohmann::json& r = line["result"];
    const std::string tool = r["tool"], cell = r["cell"];
    agg_ours.Add(tool, cell, r["ours"]);
    if (r.contains("thesis_config")) {
      agg_thesis.Add(tool, cell, r["thesis_config"]);
      const double t_ours = r["ours"]["ms"]["total"], t_thesis = r["thesis_config"]["ms"]["total"];
      if (t_ours > 0 && t_thesis > 0) speedups.push_back(t_thesis / t_ours);
    }
    if (r.contains("episode")) {
      episode_mode = true;
      const nlohmann::json& e = r["episode"];
      const bool grasped = e.value("grasp_success", false);
      grasp_by_tool_cell[tool][cell].Add(grasped);
      grasp_by_cell[cell].Add(grasped);
      grasp_by_family[family_of[tool]].Add(grasped);
      for (const char* key : {"grasp_success", "assisted", "pull_success", "ball_grasp_success"}) {
        outcomes[key].Add(e.value(key, false));
      }
      const std::string failure = e.value("failure", std::string());
      if (!failure.empty()) ++failures[failure.substr(0, failure.find(':'))];
    }
  }
  nlohmann::json summary = agg_ours.Json();
  summary["protocol"] = "table53";
  summary["mode"] = episode_mode ? "episodes" : "perception";
  summary["cells"] = cells;
  summary["seed"] = request.seed;
  summary["failed_cases"] = failed;
  if (!episode_mode) {
    summary["thesis_config"] = agg_thesis.Json();
    summary["speedup_vs_thesis_config_median"] = Percentile(speedups, 50);
  }
  summary["scoring"] =
      "1: handle axis within 15 deg, handle centre within 2 cm, effector direction within 60 deg; 0.5: flipped "
      "end to end or effector on another side; 0: otherwise (design.md)";
  auto rate_json = [](const Tally& t) {
    const auto [lo, hi] = WilsonInterval(t.ok, t.n);
    return nlohmann::json{{"rate", t.Rate()}, {"successes", t.ok}, {"n", t.n}, {"ci95", {lo, hi}}};
  };
  if (episode_mode) {
    for (const auto& [name, t] : outcomes) summary["episode"][name] = rate_json(t);
    for (const auto& [cell, t] : grasp_by_cell) summary["episode"]["grasp_success_per_cell"][cell] = rate_json(t);
    summary["episode"]["failures"] = failures;
  }
  WriteJson(request.out_dir / "summary.json", summary);

  auto value = [](const nlohmann::json& j, const char* key) {
    return j.contains(key) && j[key].is_number() ? j[key].get<double>() : std::nan("");
  };
  std::ostringstream md;
  md << "# Table 5.3 — perception accuracy per tool and cell"
     << (episode_mode ? " (full episodes)" : "") << "\n\n";
  if (episode_mode) {
    md << "Each library tool alone on the rack in each cell, one full episode per case (the ball out of reach): the "
          "episode's own rack frame and analysis scored against simulator ground truth, and whether the robot "
          "then grasped the tool, pulled the ball within reach and grasped the ball (";
  } else {
    md << "Each library tool alone on the rack in each cell; one noisy helmet frame per case, scored against "
          "simulator ground truth (";
  }
  md << summary["scoring"].get<std::string>() << "). Seed " << request.seed << ", " << agg_ours.scores.size()
     << " cases scored, " << failed << " failed to run (see results.jsonl).\n\n"
     << "| | mean score | perfect | zero | recognition | handle error median / p90 | time per tool (median) |\n"
     << "|---|---|---|---|---|---|---|\n";
  std::vector<std::pair<const char*, const Aggregate*>> methods = {{"ours", &agg_ours}};
  if (!episode_mode) methods.emplace_back("thesis configuration", &agg_thesis);
  for (const auto& [label, a] : methods) {
    const nlohmann::json j = a->Json();
    const nlohmann::json stages = j.value("per_stage_ms_median", nlohmann::json::object());
    md << "| " << label << " | " << Score(a->Mean()) << " | " << fmt::format("{:.0f} %", 100 * a->Share(1.0)) << " | "
       << fmt::format("{:.0f} %", 100 * a->Share(0.0)) << " | "
       << fmt::format("{:.0f} %", 100 * value(j, "recognition_accuracy")) << " | "
       << fmt::format("{:.1f} / {:.1f} mm", 1000 * value(j, "handle_error_median_m"),
                      1000 * value(j, "handle_error_p90_m"))
       << " | " << fmt::format("{:.0f} ms", value(stages, "total")) << " |\n";
  }
  md << "| thesis, published (29 tools, scored by eye) | 0.77 | 69 % | 16 % | – | – | – |\n\n";
  if (!episode_mode) {
    md << "Speed-up of ours over the thesis configuration on the same frames (median of per-case ratios): "
       << fmt::format("{:.1f}x", Percentile(speedups, 50)) << "\n\n";
  }
  if (episode_mode) {
    md << "| episode outcome | rate | 95 % interval | n |\n|---|---|---|---|\n";
    for (const auto& [name, t] : outcomes) {
      const auto [lo, hi] = WilsonInterval(t.ok, t.n);
      md << fmt::format("| {} | {:.0f} % | {:.0f}–{:.0f} % | {} |\n", name, 100 * t.Rate(), 100 * lo, 100 * hi, t.n);
    }
    md << "\n";
  }
  md << "## Ours\n\n" << ToolTable(agg_ours, cells);
  if (!episode_mode) md << "\n## Thesis configuration (same frames)\n\n" << ToolTable(agg_thesis, cells);
  if (episode_mode) {
    md << "\n## Grasp outcome per tool and cell (share of episodes whose tool was lifted off the rack)\n\n"
       << "| tool name";
    for (const std::string& c : cells) md << " | " << c;
    md << " |\n|---";
    for (size_t i = 0; i < cells.size(); ++i) md << "|---";
    md << "|\n";
    for (const auto& [tool, by_cell] : grasp_by_tool_cell) {
      md << "| " << tool;
      for (const std::string& c : cells) {
        const auto it = by_cell.find(c);
        md << " | " << (it == by_cell.end() ? std::string("–") : fmt::format("{:.0f} %", 100 * it->second.Rate()));
      }
      md << " |\n";
    }
    md << "| **all**";
    for (const std::string& c : cells) {
      const auto it = grasp_by_cell.find(c);
      md << " | **" << (it == grasp_by_cell.end() ? std::string("–") : fmt::format("{:.0f} %", 100 * it->second.Rate()))
         << "**";
    }
    md << " |\n";
    if (!failures.empty()) {
      md << "\n| first failure | cases |\n|---|---|\n";
      for (const auto& [name, n] : failures) md << "| " << name << " | " << n << " |\n";
    }
  }
  const std::map<std::string, FamilyRow> families = FamilyMeans(agg_ours, agg_thesis, library);
  md << "\n## Per family\n\n" << FamilyTable(families, agg_ours, agg_thesis);

  // Plots: score per cell and per family (ours, the thesis configuration, the thesis's published
  // numbers where the cell or family has a counterpart), per tool, and in episode mode the grasp
  // success per cell.
  if (!agg_ours.scores.empty()) {
    md << "\n## Plots\n\n";
    const std::map<std::string, double> ours_cells = CellMeans(agg_ours), thesis_cells = CellMeans(agg_thesis);
    BarChart per_cell;
    per_cell.title = "Table 5.3: mean score per cell";
    per_cell.x_label = "cell (extended cells compared with the thesis cell of the same pose)";
    per_cell.y_label = "mean score (0, 0.5 or 1 per case)";
    per_cell.y_max = 1.1;
    per_cell.value_labels = cells.size() * (episode_mode ? 2 : 3) <= 24;
    per_cell.value_decimals = 2;
    BarSeries s_ours{"ours", {}, {}, {}}, s_thesis{"thesis configuration (same frames)", {}, {}, {}},
        s_published{"thesis, published", {}, {}, {}};
    for (const std::string& c : cells) {
      per_cell.categories.push_back(c);
      const auto it = ours_cells.find(c);
      s_ours.values.push_back(it == ours_cells.end() ? std::nan("") : it->second);
      const auto jt = thesis_cells.find(c);
      s_thesis.values.push_back(jt == thesis_cells.end() ? std::nan("") : jt->second);
      s_published.values.push_back(PublishedCellMean(ThesisCounterpart(c)));
    }
    per_cell.series.push_back(s_ours);
    if (!episode_mode) per_cell.series.push_back(s_thesis);
    per_cell.series.push_back(s_published);
    WriteBarChartPng(per_cell, request.out_dir / "score_per_cell.png");
    md << MarkdownImage("mean score per cell", "score_per_cell.png") << "\n";

    BarChart per_family = per_cell;
    per_family.title = "Table 5.3: mean score per tool family";
    per_family.x_label = "tool family (hammer: no counterpart in the thesis)";
    per_family.categories.clear();
    per_family.series.clear();
    s_ours.values.clear();
    s_thesis.values.clear();
    s_published.values.clear();
    for (const auto& [family, row] : families) {
      per_family.categories.push_back(family);
      s_ours.values.push_back(row.ours);
      s_thesis.values.push_back(row.thesis_config);
      s_published.values.push_back(row.published);
    }
    per_family.series = {s_ours};
    if (!episode_mode) per_family.series.push_back(s_thesis);
    per_family.series.push_back(s_published);
    per_family.value_labels = true;
    WriteBarChartPng(per_family, request.out_dir / "score_per_family.png");
    md << MarkdownImage("mean score per family", "score_per_family.png") << "\n";

    BarChart per_tool;
    per_tool.title = "Table 5.3: mean score per tool over its cells";
    per_tool.x_label = "tool";
    per_tool.y_label = "mean score";
    per_tool.y_max = 1.1;
    per_tool.width_px = 1600;
    s_ours.values.clear();
    s_thesis.values.clear();
    for (const auto& [tool, by_cell] : agg_ours.cell) {
      per_tool.categories.push_back(tool);
      std::vector<double> all;
      for (const auto& [c, v] : by_cell) all.insert(all.end(), v.begin(), v.end());
      s_ours.values.push_back(Mean(all));
      std::vector<double> base;
      const auto it = agg_thesis.cell.find(tool);
      if (it != agg_thesis.cell.end()) {
        for (const auto& [c, v] : it->second) base.insert(base.end(), v.begin(), v.end());
      }
      s_thesis.values.push_back(Mean(base));
    }
    per_tool.series = {s_ours};
    if (!episode_mode) per_tool.series.push_back(s_thesis);
    WriteBarChartPng(per_tool, request.out_dir / "score_per_tool.png");
    md << MarkdownImage("mean score per tool", "score_per_tool.png") << "\n";

    if (episode_mode) {
      BarChart grasp;
      grasp.title = "Table 5.3 episodes: tool grasp success per cell (95 % Wilson intervals)";
      grasp.x_label = "cell";
      grasp.y_label = "grasp success [%]";
      grasp.y_max = 112;
      grasp.value_labels = true;
      std::vector<Tally> tallies;
      for (const std::string& c : cells) {
        grasp.categories.push_back(c);
        tallies.push_back(grasp_by_cell[c]);
      }
      grasp.series.push_back(RateSeries("", tallies));
      WriteBarChartPng(grasp, request.out_dir / "grasp_per_cell.png");
      md << MarkdownImage("grasp success per cell", "grasp_per_cell.png") << "\n";
    }
  }
  WriteTextFile(request.out_dir / "table53.md", md.str());
  WriteTextFile(request.out_dir / "summary.md", md.str());
}

}  // namespace toolbench::app
