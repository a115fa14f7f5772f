#pragma once

#include "app/bench.h"

namespace toolbench::app {

/// `toolbench bench --protocol table53`: every library tool alone on the rack
/// in each of the 7 Table 5.3 cells (pos1-pos3, rot0-rot3, design.md), or with
/// request.extended the 12 cells pos<i>_rot<j> of sim::kExtendedCellNames.
/// Perception mode (request.episodes == 0): one helmet frame per case,
/// analysed by the default perception pipeline and, on the same frame, by the
/// thesis's configuration (AnalyzerOptions::Thesis), each scored against ground
/// truth with ScoreCell. Episode mode (request.episodes = N > 0): N full
/// episodes (RunEpisode) per cell with that tool alone, the episode's own rack
/// analysis scored the same way, plus its grasp, pull and ball outcomes. Cases
/// "<tool>/<cell>" (episode mode with N > 1: "<tool>/<cell>/<k>") run through
/// RunSweep (results.jsonl, --jobs, --resume, --shard). Writes table53.md (= summary.md: the
/// thesis's layout, the thesis's published numbers per cell and family beside
/// ours, totals, PNG charts) and summary.json (mean_score, share_perfect,
/// share_zero, recognition_accuracy, handle_error_median_m, handle_error_p90_m,
/// per_stage_ms_median; perception mode: the same under thesis_config and the
/// speed-up; episode mode: "episode" with outcome rates and 95 % intervals).
int RunTable53Bench(const BenchRequest& request);

/// Writes summary.json and table53.md from table53 results lines (this run's or merged shards').
void ReportTable53(const BenchRequest& request, const std::vector<SweepLine>& lines);

}  // namespace toolbench::app
