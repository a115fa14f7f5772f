#include "app/sweep.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <thread>

#include "common/check.h"
#include "common/paths.h"

namespace toolbench::app {
namespace {

using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

std::string Duration(double s) {
  if (!std::isfinite(s) || s < 0) return "?";
  const int total = static_cast<int>(std::lround(s));
  if (total >= 3600) return fmt::format("{}h{:02d}m", total / 3600, (total / 60) % 60);
  if (total >= 60) return fmt::format("{}m{:02d}s", total / 60, total % 60);
  return fmt::format("{}s", total);
}

/// Progress on stderr: a redrawn bar on a terminal, one plain line per case otherwise.
class Progress {
 public:
  Progress(std::string protocol, int total) : protocol_(std::move(protocol)), total_(total), tty_(isatty(2) != 0) {}

  void CaseDone(const SweepLine& line) {
    ++done_;
    if (!line.value("ok", false)) ++failed_;
    const double elapsed = Seconds(start_);
    const double eta = done_ > 0 ? elapsed / done_ * (total_ - done_) : NAN;
    if (tty_) {
      const int width = 30;
      const int filled = total_ > 0 ? width * done_ / total_ : width;
      std::fprintf(stderr, "\r%s [%s%s] %d/%d  failed %d  elapsed %s  ETA %s   ", protocol_.c_str(),
                   std::string(static_cast<size_t>(filled), '#').c_str(),
                   std::string(static_cast<size_t>(width - filled), '.').c_str(), done_, total_, failed_,
                   Duration(elapsed).c_str(), Duration(eta).c_str());
      if (done_ == total_) std::fprintf(stderr, "\n");
    } else {
      std::fprintf(stderr, "%s %d/%d %s %s (%.1f s)%s%s  ETA %s\n", protocol_.c_str(), done_, total_,
                   line.value("id", "").c_str(), line.value("ok", false) ? "ok" : "FAILED", line.value("wall_s", 0.0),
                   line.value("ok", false) ? "" : ": ", line.value("ok", false) ? "" : line.value("error", "").c_str(),
                   Duration(eta).c_str());
    }
    std::fflush(stderr);
  }

 private:
  std::string protocol_;
  int total_;
  bool tty_;
  int done_ = 0;
  int failed_ = 0;
  Clock::time_point start_ = Clock::now();
};

SweepLine MakeLine(const SweepOptions& options, const SweepCase& c) {
  return {{"protocol", options.protocol}, {"index", c.index}, {"id", c.id}};
}

/// Runs one case in this process; never throws.
SweepLine RunInProcess(const SweepOptions& options, const SweepCase& c,
                       const std::function<nlohmann::json(const SweepCase&)>& run_case) {
  SweepLine line = MakeLine(options, c);
  const auto start = Clock::now();
  try {
    line["result"] = run_case(c);
    line["ok"] = true;
    line["error"] = "";
  } catch (const std::exception& e) {
    line["ok"] = false;
    line["error"] = std::string("exception: ") + e.what();
  }
  line["wall_s"] = Seconds(start);
  return line;
}

struct Child {
  pid_t pid = -1;
  SweepCase c;
  Clock::time_point start;
  std::filesystem::path result_file;
};

/// What a finished child left: its result file, or why there is none.
SweepLine Collect(const SweepOptions& options, const Child& child, int status) {
  SweepLine line = MakeLine(options, child.c);
  std::ifstream in(child.result_file);
  if (in) {
    try {
      line = nlohmann::json::parse(in);
    } catch (const std::exception& e) {
      line["ok"] = false;
      line["error"] = std::string("unreadable result: ") + e.what();
    }
  } else if (WIFSIGNALED(status)) {
    line["ok"] = false;
    line["error"] = fmt::format("crashed: signal {} ({}); log: logs/{}.log", WTERMSIG(status),
                                strsignal(WTERMSIG(status)), child.c.index);
  } else {
    line["ok"] = false;
    line["error"] = fmt::format("exited with code {} without a result; log: logs/{}.log",
                                WIFEXITED(status) ? WEXITSTATUS(status) : -1, child.c.index);
  }
  std::error_code ignored;
  std::filesystem::remove(child.result_file, ignored);
  line["wall_s"] = Seconds(child.start);
  return line;
}

Child Spawn(const SweepOptions& options, const SweepCase& c,
            const std::function<nlohmann::json(const SweepCase&)>& run_case) {
  Child child;
  child.c = c;
  child.start = Clock::now();
  child.result_file = options.out_dir / "logs" / fmt::format("{}.result.json", c.index);
  const std::filesystem::path log = options.out_dir / "logs" / fmt::format("{}.log", c.index);
  std::fflush(nullptr);
  child.pid = fork();
  if (child.pid < 0) ThrowInvalid("RunSweep: fork failed: ", std::strerror(errno));
  if (child.pid == 0) {
    // Child: logs to its own file, result through a file written atomically, then _exit (no
    // static destructors of the parent's state).
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
      close(fd);
    }
    SweepLine line = RunInProcess(options, c, run_case);
    if (!line["ok"].get<bool>()) std::fprintf(stderr, "%s\n", line["error"].get<std::string>().c_str());
    const std::filesystem::path tmp = child.result_file.string() + ".tmp";
    {
      std::ofstream out(tmp);
      out << line.dump() << "\n";
    }
    std::filesystem::rename(tmp, child.result_file);
    std::fflush(nullptr);
    _exit(0);
  }
  return child;
}

}  // namespace

void SweepOptions::Validate() const {
  if (out_dir.empty()) ThrowInvalid("SweepOptions: out_dir is empty");
  if (shard_count < 1 || shard_index < 0 || shard_index >= shard_count) {
    ThrowInvalid("SweepOptions: shard ", shard_index, "/", shard_count, " is not valid (expected 0 <= i < N)");
  }
  if (limit < 0) ThrowInvalid("SweepOptions: limit = ", limit, " (expected >= 0)");
  if (jobs < 1) ThrowInvalid("SweepOptions: jobs = ", jobs, " (expected >= 1)");
  if (!(case_timeout_s > 0)) ThrowInvalid("SweepOptions: case_timeout_s = ", case_timeout_s, " (expected > 0)");
}

std::vector<SweepLine> ReadSweepResults(const std::vector<std::filesystem::path>& dirs) {
  std::map<std::string, SweepLine> by_id;
  std::string protocol;
  for (const auto& dir : dirs) {
    const std::filesystem::path file = dir / "results.jsonl";
    std::ifstream in(file);
    if (!in) ThrowInvalid("no results.jsonl in '", dir.string(), "'");
    std::string text;
    int number = 0;
    while (std::getline(in, text)) {
      ++number;
      if (text.empty()) continue;
      SweepLine line;
      try {
        line = nlohmann::json::parse(text);
      } catch (const std::exception& e) {
        ThrowInvalid(file.string(), ":", number, ": not a JSON line (", e.what(), ")");
      }
      if (!line.contains("id") || !line.contains("index") || !line.contains("ok") || !line.contains("protocol")) {
        ThrowInvalid(file.string(), ":", number, ": a results line needs protocol, index, id and ok");
      }
      const std::string p = line["protocol"];
      if (protocol.empty()) protocol = p;
      if (p != protocol) {
        ThrowInvalid(file.string(), ":", number, ": protocol '", p, "' differs from '", protocol,
                     "' of the other lines");
      }
      // The id is read first: json's operator= takes its argument by value, and C++17 evaluates
      // (moves) the right operand before the left one.
      const std::string id = line["id"];
      by_id[id] = std::move(line);
    }
  }
  std::vector<SweepLine> lines;
  for (auto& [id, line] : by_id) lines.push_back(std::move(line));
  std::sort(lines.begin(), lines.end(),
            [](const SweepLine& a, const SweepLine& b) { return a["index"].get<int>() < b["index"].get<int>(); });
  return lines;
}

std::vector<SweepLine> RunSweep(const SweepOptions& options, const std::vector<SweepCase>& cases,
                                const std::function<nlohmann::json(const SweepCase&)>& run_case,
                                const std::function<void(const std::vector<SweepCase>&)>& prepare) {
  options.Validate();
  std::filesystem::create_directories(options.out_dir / "logs");
  const std::filesystem::path results = options.out_dir / "results.jsonl";

  std::set<std::string> finished;
  if (options.resume && std::filesystem::exists(results)) {
    for (const SweepLine& line : ReadSweepResults({options.out_dir})) finished.insert(line["id"].get<std::string>());
  } else {
    std::filesystem::remove(results);
  }
  nlohmann::json info = options.run_info;
  info["protocol"] = options.protocol;
  info["shard_index"] = options.shard_index;
  info["shard_count"] = options.shard_count;
  info["limit"] = options.limit;
  info["filter"] = options.filter;
  WriteTextFile(options.out_dir / "run.json", info.dump(2) + "\n");

  std::regex filter;
  try {
    filter = std::regex(options.filter.empty() ? ".*" : options.filter);
  } catch (const std::regex_error& e) {
    ThrowInvalid("RunSweep: filter '", options.filter, "' is not a valid regular expression (", e.what(), ")");
  }
  std::vector<SweepCase> pending;
  int in_shard = 0;
  for (const SweepCase& c : cases) {
    if (c.index % options.shard_count != options.shard_index) continue;
    if (!std::regex_search(c.id, filter)) continue;
    if (options.limit > 0 && in_shard >= options.limit) break;
    ++in_shard;
    if (finished.count(c.id) == 0) pending.push_back(c);
  }
  if (prepare) prepare(pending);
  std::ofstream out(results, std::ios::app);
  if (!out) ThrowInvalid("RunSweep: cannot write ", results.string());
  Progress progress(options.protocol, static_cast<int>(pending.size()));
  auto record = [&](const SweepLine& line) {
    out << line.dump() << "\n" << std::flush;
    progress.CaseDone(line);
  };

  if (!options.isolate) {
    for (const SweepCase& c : pending) record(RunInProcess(options, c, run_case));
  } else {
    std::vector<Child> running;
    size_t next = 0;
    while (next < pending.size() || !running.empty()) {
      while (next < pending.size() && static_cast<int>(running.size()) < options.jobs) {
        running.push_back(Spawn(options, pending[next++], run_case));
      }
      int status = 0;
      const pid_t pid = waitpid(-1, &status, WNOHANG);
      if (pid > 0) {
        const auto it = std::find_if(running.begin(), running.end(), [&](const Child& c) { return c.pid == pid; });
        if (it != running.end()) {
          record(Collect(options, *it, status));
          running.erase(it);
        }
        continue;
      }
      for (Child& child : running) {
        if (Seconds(child.start) > options.case_timeout_s && child.pid > 0) {
          kill(child.pid, SIGKILL);
          waitpid(child.pid, &status, 0);
          SweepLine line = MakeLine(options, child.c);
          line["ok"] = false;
          line["error"] =
              fmt::format("timeout: killed after {:.0f} s; log: logs/{}.log", options.case_timeout_s, child.c.index);
          line["wall_s"] = Seconds(child.start);
          record(line);
          child.pid = -1;
        }
      }
      running.erase(std::remove_if(running.begin(), running.end(), [](const Child& c) { return c.pid < 0; }),
                    running.end());
      // Short cases (ik: milliseconds) should not wait long for their slot.
      std::this_thread::sleep_for(std::chrono::milliseconds(running.empty() ? 0 : 3));
    }
  }
  out.close();
  return ReadSweepResults({options.out_dir});
}

}  // namespace toolbench::app
