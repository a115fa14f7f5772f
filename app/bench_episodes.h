#pragma once

#include <vector>

#include "app/bench.h"

namespace toolbench::app {

/// `toolbench bench --protocol random --episodes N --seed S`: N full episodes (RunEpisode) with
/// randomized tools, cells and ball positions (episode i uses scene seed DeriveSeed(S, "random/i")),
/// each in its own child process, one results.jsonl line each (see RunSweep).
int RunRandomEpisodesBench(const BenchRequest& request);

/// Writes summary.json and summary.md from random-episode results lines: success rates of grasp,
/// pull and ball grasp with 95 % Wilson intervals, assisted share, stage-time medians and 90th
/// percentiles, wall time per episode.
void ReportRandomEpisodes(const BenchRequest& request, const std::vector<SweepLine>& lines);

}  // namespace toolbench::app
