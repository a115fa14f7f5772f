#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace toolbench::app {

/// What `toolbench bench` was asked to do.
struct BenchRequest {
  std::string protocol;                       // name of a registered protocol
  std::filesystem::path out_dir;              // results go here (created)
  std::uint64_t seed = 1;                     // master seed of the run
  int shard_index = 0;                        // this process runs cases i with i % shard_count == shard_index
  int shard_count = 1;                        // >= 1
  int limit = 0;                              // run at most this many cases (0 = all), for quick looks
  bool frames = false;                        // protocols that support it write overview PNGs per case
  std::string match;                          // run only cases whose "tool/cell" contains this (empty = all)
};

/// One benchmark protocol: runs its cases, writes `summary.json` (and whatever else it likes) to
/// request.out_dir, returns the process exit code (0 when the run completed, even if some cases
/// failed: failed cases are recorded with their reason, never lost).
struct BenchProtocol {
  std::string name;
  std::string description;
  std::function<int(const BenchRequest&)> run;
};

/// All protocols, in the order `toolbench bench --help` lists them.
std::vector<BenchProtocol> BenchProtocols();

/// Runs the protocol named in the request; throws std::invalid_argument for an unknown name.
int RunBench(const BenchRequest& request);

/// Whether case `index` belongs to this shard.
inline bool InShard(const BenchRequest& request, int index) {
  return index % request.shard_count == request.shard_index;
}

/// Whether a case named "tool/cell" passes the request's --match filter.
inline bool Matches(const BenchRequest& request, const std::string& name) {
  return request.match.empty() || name.find(request.match) != std::string::npos;
}

/// Writes JSON to a file with a trailing newline (creating folders).
void WriteJson(const std::filesystem::path& path, const nlohmann::json& value);

/// Median and percentile (linear interpolation, p in [0, 100]) of a sample; NaN when empty.
double Percentile(std::vector<double> values, double p);

}  // namespace toolbench::app
