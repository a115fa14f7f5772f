#include "app/bench.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "app/bench_grasp.h"
#include "app/bench_ik.h"
#include "app/bench_pull.h"
#include "common/check.h"
#include "common/paths.h"

namespace toolbench::app {

std::vector<BenchProtocol> BenchProtocols() {
  // Protocols are listed here explicitly (no static registration: no global state).
  std::vector<BenchProtocol> protocols;
  protocols.push_back({"ik", "Cartesian solver: 500 reachable + 100 unreachable palm poses, default vs plain Ipopt",
                       RunIkBench});
  protocols.push_back({"grasp-gt",
                       "Grasp + lift + 2 s hold of every library tool in the 7 Table 5.3 cells, from the "
                       "ground-truth handle pose",
                       RunGraspBench});
  protocols.push_back({"pull-gt",
                       "Per library tool (cell rot0): grasp from the ground-truth handle, pull the ball lying out "
                       "of reach toward the robot, put the tool down, grasp the ball",
                       RunPullBench});
  return protocols;
}

int RunBench(const BenchRequest& request) {
  if (request.shard_count < 1 || request.shard_index < 0 || request.shard_index >= request.shard_count) {
    ThrowInvalid("bench: shard ", request.shard_index, "/", request.shard_count,
                 " is not valid (expected 0 <= i < N)");
  }
  std::string known;
  for (const BenchProtocol& protocol : BenchProtocols()) {
    if (protocol.name == request.protocol) return protocol.run(request);
    known += (known.empty() ? "" : ", ") + protocol.name;
  }
  ThrowInvalid("bench: unknown protocol '", request.protocol, "' (known: ", known.empty() ? "none yet" : known, ")");
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
