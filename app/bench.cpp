#include "app/bench.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "app/bench_episodes.h"
#include "app/bench_grasp.h"
#include "app/bench_ik.h"
#include "app/bench_table53.h"
#include "app/bench_pull.h"
#include "common/check.h"
#include "common/paths.h"
#include "sim/scene_spec.h"

namespace toolbench::app {

std::vector<BenchProtocol> BenchProtocols() {
  // Protocols are listed here explicitly (no static registration: no global state).
  std::vector<BenchProtocol> protocols;
  protocols.push_back(
      {"ik", "Cartesian solver: 500 reachable + 100 unreachable palm poses, default vs plain Ipopt", RunIkBench,
       ReportIk});
  protocols.push_back({"grasp-gt",
                       "Grasp + lift + 2 s hold of every library tool in the 7 Table 5.3 cells, from the "
                       "ground-truth handle pose; summary.md with per-cell and per-tool plots",
                       RunGraspBench, ReportGrasp});
  protocols.push_back({"pull-gt",
                       "Per library tool (cell rot0): grasp from the ground-truth handle, pull the ball lying out "
                       "of reach toward the robot, put the tool down, grasp the ball",
                       RunPullBench, ReportPull});
  protocols.push_back({"table53",
                       "Perception accuracy: every library tool in the 7 Table 5.3 cells (--extended: the 12 "
                       "of 3 places x 4 rotations), ours vs the thesis configuration on the same frames; "
                       "--episodes N: N full episodes per cell, perception score + grasp outcome; writes "
                       "table53.md and plots",
                       RunTable53Bench, ReportTable53});
  protocols.push_back({"random",
                       "Full episodes (--episodes N, default 50) with randomized tools, cells and ball positions: "
                       "choice, grasp, pull and ball-grasp rates with 95% intervals, stage times; writes summary.md "
                       "and plots",
                       RunRandomEpisodesBench, ReportRandomEpisodes});
  return protocols;
}

int RunBench(const BenchRequest& request) {
  if (request.shard_count < 1 || request.shard_index < 0 || request.shard_index >= request.shard_count) {
    ThrowInvalid("bench: shard ", request.shard_index, "/", request.shard_count, " is not valid (expected 0 <= i < N)");
  }
  if (request.episodes < 0) ThrowInvalid("bench: --episodes ", request.episodes, " (expected >= 0)");
  if (request.hindsight && request.protocol != "random") {
    ThrowInvalid("bench: --hindsight applies to protocol random only, not '", request.protocol, "'");
  }
  if (!request.check_action_before_grasp && request.protocol != "random") {
    ThrowInvalid("bench: --no-action-check applies to protocol random only, not '", request.protocol, "'");
  }
  if (!request.look_again_after_failed_grasp && request.protocol != "random") {
    ThrowInvalid("bench: --no-look-again applies to protocol random only, not '", request.protocol, "'");
  }
  if (request.from_rack_look && request.protocol != "grasp-gt") {
    ThrowInvalid("bench: --from-rack-look applies to protocol grasp-gt only, not '", request.protocol, "'");
  }
  if (request.extended && request.protocol != "table53") {
    ThrowInvalid("bench: --extended applies to protocol table53 only, not '", request.protocol, "'");
  }
  std::string known;
  for (const BenchProtocol& protocol : BenchProtocols()) {
    if (protocol.name == request.protocol) return protocol.run(request);
    known += (known.empty() ? "" : ", ") + protocol.name;
  }
  ThrowInvalid("bench: unknown protocol '", request.protocol, "' (known: ", known.empty() ? "none yet" : known, ")");
}

std::vector<SweepCase> ToolCellCases(const std::vector<std::string>& tools, const std::vector<std::string>& cells) {
  std::vector<SweepCase> cases;
  for (const std::string& tool : tools) {
    for (const std::string& cell : cells) {
      SweepCase c;
      c.index = static_cast<int>(cases.size());
      c.id = tool + "/" + cell;
      c.params = {{"tool", tool}, {"cell", cell}};
      cases.push_back(std::move(c));
    }
  }
  return cases;
}

std::vector<std::string> SortedToolNames(const std::vector<toollib::ToolModel>& library) {
  std::vector<std::string> names;
  for (const auto& t : library) names.push_back(t.name);
  std::sort(names.begin(), names.end());
  return names;
}

double Tally::Rate() const { return n > 0 ? static_cast<double>(ok) / n : std::numeric_limits<double>::quiet_NaN(); }

std::pair<double, double> WilsonInterval(int successes, int n) {
  if (n <= 0) return {0.0, 1.0};
  const double z = 1.959963984540054;
  const double p = static_cast<double>(successes) / n;
  const double denominator = 1 + z * z / n;
  const double centre = (p + z * z / (2.0 * n)) / denominator;
  const double half = z * std::sqrt(p * (1 - p) / n + z * z / (4.0 * n * n)) / denominator;
  return {std::max(0.0, centre - half), std::min(1.0, centre + half)};
}

SweepOptions SweepOptionsFor(const BenchRequest& request, const std::string& protocol, const nlohmann::json& info) {
  SweepOptions options;
  options.out_dir = request.out_dir;
  options.protocol = protocol;
  options.shard_index = request.shard_index;
  options.shard_count = request.shard_count;
  options.limit = request.limit;
  options.filter = request.filter;
  options.case_timeout_s = request.case_timeout_s;
  options.jobs = request.jobs;
  options.resume = request.resume;
  options.isolate = request.isolate;
  options.run_info = info;
  options.run_info["seed"] = request.seed;
  options.run_info["scene"] = request.scene_file.empty() ? sim::DefaultScenePath().string() : request.scene_file.string();
  return options;
}

SceneRequest BenchScene(const BenchRequest& request, std::uint64_t seed) {
  SceneRequest scene;
  scene.scene_file = request.scene_file;
  scene.seed = seed;
  return scene;
}

int MergeRuns(const std::vector<std::filesystem::path>& dirs, const std::filesystem::path& out_dir) {
  if (dirs.empty()) ThrowInvalid("merge: no run folders given");
  const std::vector<SweepLine> lines = ReadSweepResults(dirs);
  if (lines.empty()) ThrowInvalid("merge: the run folders hold no results");
  const std::string protocol = lines.front()["protocol"];
  BenchRequest request;
  request.protocol = protocol;
  request.out_dir = out_dir;
  // The master seed of the sweep, from the first folder's run.json (all shards share it).
  const std::filesystem::path info_file = dirs.front() / "run.json";
  if (std::filesystem::exists(info_file)) {
    const nlohmann::json info = nlohmann::json::parse(ReadTextFile(info_file));
    request.seed = info.value("seed", std::uint64_t{1});
  }
  for (const BenchProtocol& p : BenchProtocols()) {
    if (p.name != protocol) continue;
    if (!p.report) ThrowInvalid("merge: protocol '", protocol, "' does not record mergeable results");
    std::filesystem::create_directories(out_dir);
    std::string all;
    for (const SweepLine& line : lines) all += line.dump() + "\n";
    WriteTextFile(out_dir / "results.jsonl", all);
    p.report(request, lines);
    return 0;
  }
  ThrowInvalid("merge: results of unknown protocol '", protocol, "'");
}

BarSeries RateSeries(const std::string& label, const std::vector<Tally>& tallies) {
  BarSeries series;
  series.label = label;
  for (const Tally& t : tallies) {
    const auto [lo, hi] = WilsonInterval(t.ok, t.n);
    series.values.push_back(100 * t.Rate());
    series.low.push_back(t.n > 0 ? 100 * lo : std::numeric_limits<double>::quiet_NaN());
    series.high.push_back(t.n > 0 ? 100 * hi : std::numeric_limits<double>::quiet_NaN());
  }
  return series;
}

std::string MarkdownImage(const std::string& alt, const std::filesystem::path& png) {
  return "![" + alt + "](" + png.filename().string() + ")\n";
}

void WriteJson(const std::filesystem::path& path, const nlohmann::json& value) {
  WriteTextFile(path, value.dump(2) + "\n");
}

double Percentile(std::vector<double> values, double p) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(values.begin(), values.end());
  const double rank = std::clamp(p, 0.0, 100.0) / 100.0 * (values.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(rank));
  const size_t hi = std::min(values.size() - 1, lo + 1);
  return values[lo] + (values[hi] - values[lo]) * (rank - lo);
}

}  // namespace toolbench::app
