#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "app/sweep.h"

namespace toolbench::app {

/// What `toolbench bench` was asked to do.
struct BenchRequest {
  std::string protocol;           // name of a registered protocol
  std::filesystem::path out_dir;  // results go here (created)
  std::uint64_t seed = 1;         // master seed of the run
  int shard_index = 0;            // this process runs cases i with i % shard_count == shard_index
  int shard_count = 1;            // >= 1
  int limit = 0;                  // run at most this many cases (0 = all), for quick looks
  std::string filter;             // regex on case ids ("hoe_1/rot.*"); empty = all
  int episodes = 50;              // episode protocols: how many episodes, >= 1
  double case_timeout_s = 900;    // a case running longer is killed and recorded as failed [s], > 0
  int jobs = 1;                   // cases run at once, each in its own child process, >= 1
  bool resume = false;            // skip cases already recorded in out_dir/results.jsonl
  bool isolate = true;            // false: run cases in this process (for a debugger)
  bool frames = false;            // protocols that support it write overview PNGs per case
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

/// All protocols, in the order `toolbench bench --help` lists them.
std::vector<BenchProtocol> BenchProtocols();

/// Runs the protocol named in the request; throws std::invalid_argument for an unknown name.
int RunBench(const BenchRequest& request);

/// Whether case `index` belongs to this shard.
inline bool InShard(const BenchRequest& request, int index) {
  return index % request.shard_count == request.shard_index;
}

/// Sweep options from a bench request (out_dir, shard, limit, jobs, resume, isolate); `info`
/// goes into run.json.
SweepOptions SweepOptionsFor(const BenchRequest& request, const std::string& protocol,
                             const nlohmann::json& info = nlohmann::json::object());

/// `toolbench merge`: joins the results.jsonl of several run folders (shards) of one protocol
/// and writes that protocol's report to out_dir. Throws std::invalid_argument for folders of
/// different protocols, a protocol without a report, or malformed results.
int MergeRuns(const std::vector<std::filesystem::path>& dirs, const std::filesystem::path& out_dir);

/// Whether a case named "tool/cell" passes the request's --filter (a regular expression searched
/// in the name; empty = all). Throws std::invalid_argument for an invalid expression.
bool Matches(const BenchRequest& request, const std::string& name);

/// Writes JSON to a file with a trailing newline (creating folders).
void WriteJson(const std::filesystem::path& path, const nlohmann::json& value);

/// Median and percentile (linear interpolation, p in [0, 100]) of a sample; NaN when empty.
double Percentile(std::vector<double> values, double p);

}  // namespace toolbench::app
