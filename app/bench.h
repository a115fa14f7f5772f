#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "app/plots.h"
#include "app/scene_setup.h"
#include "app/sweep.h"
#include "toollib/tool_model.h"

namespace toolbench::app {

/// What `toolbench bench` was asked to do.
struct BenchRequest {
  std::string protocol;           // name of a registered protocol
  std::filesystem::path out_dir;  // results go here (created)
  std::uint64_t seed = 1;         // master seed of the run
  std::filesystem::path scene_file;  // scene of every case; empty = scenes/default.json
  int shard_index = 0;            // this process runs cases i with i % shard_count == shard_index
  int shard_count = 1;            // >= 1
  int limit = 0;                  // run at most this many cases (0 = all), for quick looks
  std::string filter;             // regex on case ids ("hoe_1/rot.*"); empty = all
  int episodes = 0;               // random: how many episodes (0 = 50); table53: full episodes per
                                  // cell instead of single frames (0 = perception only), >= 0
  bool extended = false;          // table53: the 12 cells of the 3 x 4 cross product instead of 7
  double case_timeout_s = 900;    // a case running longer is killed and recorded as failed [s], > 0
  int jobs = 1;                   // cases run at once, each in its own child process, >= 1
  bool resume = false;            // skip cases already recorded in out_dir/results.jsonl
  bool isolate = true;            // false: run cases in this process (for a debugger)
  bool frames = false;            // protocols that support it write overview PNGs per case
  /// random: after each episode that needed a tool, pull with every tool of its rack from the
  /// tool's ground-truth handle (pull-gt's case: that tool alone in its cell, the episode's ball)
  /// and score the episode's choice against the best of them (truth.choice_correct).
  bool hindsight = false;
  bool best_tool_only = false;    // random: EpisodeRequest::best_tool_only (table53 scenes hold one tool)
  bool check_action_before_grasp = true;  // random: EpisodeRequest::check_action_before_grasp
  bool look_again_after_failed_grasp = true;  // random: EpisodeRequest::look_again_after_failed_grasp
  bool from_rack_look = false;    // grasp-gt: GraspCaseOptions::from_rack_look
};

/// One benchmark protocol: runs its cases, writes `summary.json` (and whatever else it likes) to
/// request.out_dir, returns the process exit code (0 when the run completed, even if some cases
/// failed: failed cases are recorded with their reason, never lost).
struct BenchProtocol {
  std::string name;
  std::string description;
  std::function<int(const BenchRequest&)> run;
  /// For protocols that record results.jsonl (RunSweep): writes the report (summary.json and
  /// more) from results lines, e.g. of several shards (`toolbench merge`). Empty otherwise.
  std::function<void(const BenchRequest&, const std::vector<SweepLine>&)> report;
};

/// The scene a bench case runs in: request.scene_file, and `seed` (a case's own, or the run's).
SceneRequest BenchScene(const BenchRequest& request, std::uint64_t seed);

/// All protocols, in the order `toolbench bench --help` lists them.
std::vector<BenchProtocol> BenchProtocols();

/// Runs the protocol named in the request; throws std::invalid_argument for an unknown name.
int RunBench(const BenchRequest& request);

/// Sweep options from a bench request (out_dir, shard, limit, jobs, resume, isolate); `info`
/// goes into run.json.
SweepOptions SweepOptionsFor(const BenchRequest& request, const std::string& protocol,
                             const nlohmann::json& info = nlohmann::json::object());

/// `toolbench merge`: joins the results.jsonl of several run folders (shards) of one protocol
/// and writes that protocol's report to out_dir. Throws std::invalid_argument for folders of
/// different protocols, a protocol without a report, or malformed results.
int MergeRuns(const std::vector<std::filesystem::path>& dirs, const std::filesystem::path& out_dir);

/// Cases "<tool>/<cell>" for every tool and cell, params {"tool", "cell"}, index = tool index *
/// cells.size() + cell index (so shards and --resume see the same numbering on every machine).
std::vector<SweepCase> ToolCellCases(const std::vector<std::string>& tools, const std::vector<std::string>& cells);

/// Names of the library's tools, sorted (the case order of the per-tool protocols).
std::vector<std::string> SortedToolNames(const std::vector<toollib::ToolModel>& library);

/// Successes out of trials.
struct Tally {
  int n = 0;   // trials
  int ok = 0;  // successes, <= n
  void Add(bool success) {
    ++n;
    ok += success ? 1 : 0;
  }
  double Rate() const;  // ok / n; NaN when n = 0
};

/// 95 % Wilson score interval of a binomial proportion: {low, high}; {0, 1} for n = 0.
std::pair<double, double> WilsonInterval(int successes, int n);

/// A bar series of success rates in percent with their 95 % Wilson intervals, one per tally
/// (NaN bars for empty tallies).
BarSeries RateSeries(const std::string& label, const std::vector<Tally>& tallies);

/// The markdown line that shows a PNG of the same folder: "![alt](file)\n".
std::string MarkdownImage(const std::string& alt, const std::filesystem::path& png);

/// Writes JSON to a file with a trailing newline (creating folders).
void WriteJson(const std::filesystem::path& path, const nlohmann::json& value);

/// Median and percentile (linear interpolation, p in [0, 100]) of a sample; NaN when empty.
double Percentile(std::vector<double> values, double p);

}  // namespace toolbench::app
