#pragma once

#include "app/bench.h"

namespace toolbench::app {

/// `toolbench bench --protocol table53`: every library tool alone on the rack
/// in each of the 7 Table 5.3 cells (pos1-pos3, rot0-rot3, design.md); one
/// helmet frame per case, analysed by the default perception pipeline and, on
/// the same frame, by the thesis's configuration (AnalyzerOptions::Thesis);
/// each scored against ground truth with ScoreCell. Writes `cases.jsonl` (one
/// line per case, as it finishes; a case that throws is recorded with its
/// reason), `table53.md` (the thesis's layout, ours and the thesis
/// configuration, the thesis's published numbers per family beside them) and
/// `summary.json` (mean_score, share_perfect, share_zero, recognition_accuracy,
/// handle_error_median_m, handle_error_p90_m, per_stage_ms_median, the same for
/// the baseline, and the speed-up).
int RunTable53Bench(const BenchRequest& request);

/// Writes summary.json and table53.md from table53 results lines (this run's or merged shards').
void ReportTable53(const BenchRequest& request, const std::vector<SweepLine>& lines);

}  // namespace toolbench::app
