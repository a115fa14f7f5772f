#pragma once

#include <vector>

#include "app/bench.h"

namespace toolbench::app {

/// Protocol "ik": the Cartesian solver on 500 seeded reachable targets (palm poses from forward
/// kinematics of random in-limit arm postures, warm start from the home posture) and 100
/// unreachable ones (positions 1-2 m from the shoulder, or behind the back), solved by three
/// configurations: "default" (IkOptions{}), "baseline_plain_ipopt" (no pre-solve: Ipopt from the
/// warm start, the thesis / iKin-like setup) and "presolve_then_ipopt_polish" (polish = true).
/// Success = status converged and errors <= 1 mm / 2 deg. Writes summary.json (default's figures
/// at top level: success_rate, pos_error_median_m, rot_error_median_deg, solve_ms_median,
/// solve_ms_p90, unreachable_reported_rate, ...; the baseline's under "baseline"; every
/// configuration under "configs"). A case = one target ("reachable/<i>", "unreachable/<i>"), run
/// by RunSweep: one results.jsonl line per target with every configuration's status, errors,
/// iterations and solve time ("failure" gives the reason). Returns 0 when the run completed.
int RunIkBench(const BenchRequest& request);

/// Writes summary.json from ik results lines (this run's or merged shards').
void ReportIk(const BenchRequest& request, const std::vector<SweepLine>& lines);

}  // namespace toolbench::app
