#pragma once

#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace toolbench::app {

/// One unit of work of a benchmark sweep, identified by a stable id (e.g. "hoe_1/rot2").
struct SweepCase {
  int index = 0;   // position in the full, unsharded sweep (shards take index % N == i)
  std::string id;  // unique within the sweep
  nlohmann::json params = nlohmann::json::object();  // whatever the case function needs
};

/// How to run a sweep.
struct SweepOptions {
  std::filesystem::path out_dir;                       // results.jsonl, run.json and logs/ go here (created)
  std::string protocol;                                // recorded in run.json and every line
  int shard_index = 0;                                 // run cases with index % shard_count == shard_index
  int shard_count = 1;                                 // >= 1
  std::string filter;                                  // ECMAScript regex: only cases whose id it matches (empty = all)
  int limit = 0;                                       // at most this many cases of the shard (0 = all)
  int jobs = 1;                                        // child processes at once, >= 1
  bool resume = false;                                 // skip cases already in results.jsonl (ok or failed)
  bool isolate = true;                                 // run each case in a forked child process (crash-proof);
                                                       // false runs them in this process, one at a time (debugging)
  double case_timeout_s = 900.0;                       // a child running longer is killed and recorded [s], > 0
  nlohmann::json run_info = nlohmann::json::object();  // extra fields for run.json (seed, ...)
  void Validate() const;                               // throws std::invalid_argument naming the field
};

/// One finished case, as written to results.jsonl: {"protocol", "index", "id", "ok", "error",
/// "wall_s", "result"}. `result` is what the case function returned (absent when it failed).
using SweepLine = nlohmann::json;

/// Runs the shard's cases and returns every line of the shard's results.jsonl (resumed ones
/// included), ordered by index. Each case runs in a forked child (up to `jobs` at once) whose
/// stdout/stderr go to logs/<index>.log; its result comes back through a file and the parent
/// alone appends it to results.jsonl as one line, flushed, as soon as the case ends. A case that
/// throws, exits non-zero, crashes or times out is recorded with ok = false and the reason, and
/// the sweep goes on. Progress: a bar with ETA on a terminal (stderr), a plain line per case
/// otherwise. State the cases need (loaded libraries, prepared models) is best built before
/// calling, so that children inherit it instead of rebuilding it.
/// `prepare`, when given, is called once in this process with the cases about to run (after
/// shard, filter, limit and resume), before any child starts: the place to warm caches.
std::vector<SweepLine> RunSweep(const SweepOptions& options, const std::vector<SweepCase>& cases,
                                const std::function<nlohmann::json(const SweepCase&)>& run_case,
                                const std::function<void(const std::vector<SweepCase>&)>& prepare = nullptr);

/// Reads results.jsonl files (one per shard folder) and returns their lines, the last line of an
/// id winning, ordered by index. Throws std::invalid_argument naming a folder without
/// results.jsonl, a malformed line (file and line number) or lines of different protocols.
std::vector<SweepLine> ReadSweepResults(const std::vector<std::filesystem::path>& dirs);

}  // namespace toolbench::app
