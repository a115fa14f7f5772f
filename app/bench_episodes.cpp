#include "app/bench_episodes.h"

#include <cmath>
#include <map>
#include <sstream>
#include <string>

#include <fmt/format.h>

#include "app/episode.h"
#include "common/paths.h"
#include "common/rng.h"

namespace toolbench::app {

std::pair<double, double> WilsonInterval(int successes, int n) {
  if (n <= 0) return {0.0, 1.0};
  const double z = 1.959963984540054;
  const double p = static_cast<double>(successes) / n;
  const double denominator = 1 + z * z / n;
  const double centre = (p + z * z / (2.0 * n)) / denominator;
  const double half = z * std::sqrt(p * (1 - p) / n + z * z / (4.0 * n * n)) / denominator;
  return {std::max(0.0, centre - half), std::min(1.0, centre + half)};
}

int RunRandomEpisodesBench(const BenchRequest& request) {
  std::vector<SweepCase> cases;
  for (int i = 0; i < request.episodes; ++i) {
    SweepCase c;
    c.index = i;
    c.id = "episode/" + std::to_string(i);
    c.params = {{"scene_seed", DeriveSeed(request.seed, "random/" + std::to_string(i))}};
    cases.push_back(c);
  }
  auto run_case = [&](const SweepCase& c) {
    EpisodeRequest episode;
    episode.scene.seed = c.params["scene_seed"].get<std::uint64_t>();
    episode.quiet = true;
    episode.out_dir = request.out_dir / "episodes" / std::to_string(c.index);
    return EpisodeJson(RunEpisode(episode));
  };
  nlohmann::json info;
  info["episodes"] = request.episodes;
  ReportRandomEpisodes(request, RunSweep(SweepOptionsFor(request, "random", info), cases, run_case));
  return 0;
}

void ReportRandomEpisodes(const BenchRequest& request, const std::vector<SweepLine>& lines) {
  struct Rate {
    int ok = 0;
    int n = 0;
  };
  std::map<std::string, Rate> rates;
  std::map<std::string, std::vector<double>> stage_ms;
  std::map<std::string, int> failures;
  std::vector<double> wall_s, displacement;
  int crashed = 0;
  for (const SweepLine& line : lines) {
    if (!line.value("ok", false)) {
      ++crashed;
      ++failures["crashed: " + line.value("error", std::string()).substr(0, 60)];
      continue;
    }
    const nlohmann::json& r = line["result"];
    const bool needed_tool = !r.value("ball_reachable_at_start", false);
    auto count = [&](const std::string& name, bool ok) {
      ++rates[name].n;
      rates[name].ok += ok ? 1 : 0;
    };
    if (needed_tool) {
      count("grasp_success", r.value("grasp_success", false));
      count("pull_success", r.value("pull_success", false));
      count("assisted", r.value("assisted", false));
      displacement.push_back(r.value("achieved_displacement_m", 0.0));
    }
    count("ball_grasp_success", r.value("ball_grasp_success", false));
    count("completed", r.value("failure", std::string()).empty());
    wall_s.push_back(r.value("wall_s", 0.0));
    for (const auto& s : r["stages"]) stage_ms[s["name"].get<std::string>()].push_back(s["wall_ms"].get<double>());
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
  summary["achieved_displacement_m_median"] = Percentile(displacement, 50);
  summary["wall_s_median"] = Percentile(wall_s, 50);
  summary["wall_s_p90"] = Percentile(wall_s, 90);
  for (const auto& [name, values] : stage_ms) {
    summary["stage_ms"][name] = {
        {"median", Percentile(values, 50)}, {"p90", Percentile(values, 90)}, {"n", values.size()}};
  }
  summary["failures"] = failures;
  WriteJson(request.out_dir / "summary.json", summary);

  std::ostringstream md;
  md << "# Random episodes\n\nSeed " << request.seed << ", " << lines.size() << " episodes (" << crashed
     << " crashed).\n\n| rate | value | 95 % interval | n |\n|---|---|---|---|\n";
  for (const auto& [name, rate] : rates) {
    const auto [lo, hi] = WilsonInterval(rate.ok, rate.n);
    md << fmt::format("| {} | {:.0f} % | {:.0f}–{:.0f} % | {} |\n", name, rate.n ? 100.0 * rate.ok / rate.n : NAN,
                      100 * lo, 100 * hi, rate.n);
  }
  md << "\n| stage | median ms | p90 ms |\n|---|---|---|\n";
  for (const auto& [name, values] : stage_ms) {
    md << fmt::format("| {} | {:.0f} | {:.0f} |\n", name, Percentile(values, 50), Percentile(values, 90));
  }
  md << fmt::format("\nWall time per episode: median {:.1f} s, p90 {:.1f} s.\n", Percentile(wall_s, 50),
                    Percentile(wall_s, 90));
  if (!failures.empty()) {
    md << "\n| first failure | episodes |\n|---|---|\n";
    for (const auto& [name, n] : failures) md << "| " << name << " | " << n << " |\n";
  }
  WriteTextFile(request.out_dir / "summary.md", md.str());
}

}  // namespace toolbench::app
