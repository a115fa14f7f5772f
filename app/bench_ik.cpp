#include "app/bench_ik.h"

#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "common/check.h"
#include "common/rng.h"
#include "control/ik.h"
#include "control/kinematics.h"
#include "robot/robot_description.h"

namespace toolbench::app {
namespace {

constexpr int kReachableCases = 500;
constexpr int kUnreachableCases = 100;
// Success criterion of issue 4, independent of the solver's own tolerances.
constexpr double kSuccessPosM = 1e-3;
constexpr double kSuccessRotRad = 2.0 * M_PI / 180.0;

struct IkCase {
  int index = 0;
  bool reachable = true;
  Eigen::Isometry3d X_RT = Eigen::Isometry3d::Identity();
};

// Case i draws from its own stream, so shards and limits see the same targets.
IkCase MakeCase(const BenchRequest& request, const control::KinematicChain& chain, const Eigen::VectorXd& q_home,
                int index) {
  Rng rng(DeriveSeed(request.seed, "ik_case_" + std::to_string(index)));
  IkCase c;
  c.index = index;
  c.reachable = index < kReachableCases;
  Eigen::VectorXd q_chain(chain.num_joints());
  for (int i = 0; i < q_chain.size(); ++i) q_chain[i] = UniformReal(rng, chain.lower()[i], chain.upper()[i]);
  c.X_RT = chain.TipPose(chain.ModelQ(q_home, q_chain));
  if (!c.reachable) {
    // A reachable orientation, at a position out of reach: 1-2 m away from the shoulder
    // (any direction), or behind the back (root +x is backward), alternately.
    const Eigen::Vector3d p_shoulder(-0.0108, 0.1101, 0.1753);  // icub.md section 3, frame 4
    if (index % 2 == 0) {
      Eigen::Vector3d dir(StandardNormal(rng), StandardNormal(rng), StandardNormal(rng));
      dir.normalize();
      c.X_RT.translation() = p_shoulder + UniformReal(rng, 1.0, 2.0) * dir;
    } else {
      c.X_RT.translation() = Eigen::Vector3d(UniformReal(rng, 0.3, 0.5), UniformReal(rng, -0.2, 0.3),
                                             UniformReal(rng, -0.2, 0.3));
    }
  }
  return c;
}

struct ConfigStats {
  std::vector<double> pos_error_m;   // reachable cases
  std::vector<double> rot_error_deg; // reachable cases
  std::vector<double> solve_ms;      // reachable cases
  std::vector<double> iterations;    // reachable cases
  std::vector<double> rest_cost;     // reachable cases that succeeded
  int reachable = 0;
  int succeeded = 0;
  int unreachable = 0;
  int unreachable_reported = 0;
  std::vector<double> unreachable_ms;
};

nlohmann::json Summarise(const ConfigStats& s) {
  auto rate = [](int k, int n) { return n > 0 ? static_cast<double>(k) / n : std::nan(""); };
  return {{"reachable_cases", s.reachable},
          {"success_rate", rate(s.succeeded, s.reachable)},
          {"pos_error_median_m", Percentile(s.pos_error_m, 50)},
          {"pos_error_p90_m", Percentile(s.pos_error_m, 90)},
          {"rot_error_median_deg", Percentile(s.rot_error_deg, 50)},
          {"rot_error_p90_deg", Percentile(s.rot_error_deg, 90)},
          {"solve_ms_median", Percentile(s.solve_ms, 50)},
          {"solve_ms_p90", Percentile(s.solve_ms, 90)},
          {"solve_ms_max", Percentile(s.solve_ms, 100)},
          {"iterations_median", Percentile(s.iterations, 50)},
          {"rest_cost_median", Percentile(s.rest_cost, 50)},
          {"unreachable_cases", s.unreachable},
          {"unreachable_reported_rate", rate(s.unreachable_reported, s.unreachable)},
          {"unreachable_solve_ms_median", Percentile(s.unreachable_ms, 50)}};
}

/// The three solver configurations, in summary order (default first, then the baseline).
std::vector<std::pair<std::string, control::IkOptions>> Configs() {
  std::vector<std::pair<std::string, control::IkOptions>> configs(3);
  configs[0].first = "default";  // pre-solve + rest refinement, Ipopt only when that fails
  configs[1].first = "baseline_plain_ipopt";  // thesis / iKin-like: Ipopt from the warm start
  configs[1].second.presolve = false;
  configs[2].first = "presolve_then_ipopt_polish";  // Ipopt after every pre-solve
  configs[2].second.polish = true;
  return configs;
}

}  // namespace

int RunIkBench(const BenchRequest& request) {
  const robot::RobotDescription robot = robot::LoadRobotDescription(robot::DefaultRobotSidecar());
  const control::KinematicChain chain = control::MakeRightArmChain(robot.model, robot.palm_frame);
  const Eigen::VectorXd q_home = robot.HomeQ();
  const auto configs = Configs();
  // Built once here; the case processes inherit them.
  std::vector<control::CartesianSolver> solvers;
  for (const auto& [name, options] : configs) solvers.emplace_back(chain, q_home, options);

  std::vector<SweepCase> cases;
  for (int index = 0; index < kReachableCases + kUnreachableCases; ++index) {
    SweepCase c;
    c.index = index;
    c.id = (index < kReachableCases ? "reachable/" : "unreachable/") + std::to_string(index);
    cases.push_back(c);
  }
  auto run_case = [&](const SweepCase& sweep_case) {
    const IkCase c = MakeCase(request, chain, q_home, sweep_case.index);
    const Eigen::Vector3d p = c.X_RT.translation();
    nlohmann::json out = {{"reachable", c.reachable}, {"target_p_R", {p.x(), p.y(), p.z()}}};
    for (size_t k = 0; k < configs.size(); ++k) {
      const control::IkResult r = solvers[k].Solve(c.X_RT, q_home);
      const bool within = r.position_error_m <= kSuccessPosM && r.orientation_error_rad <= kSuccessRotRad;
      const bool converged = r.status == control::IkStatus::kConverged;
      // Reachable: converged within tolerance; unreachable: reported as not converged.
      const bool success = c.reachable ? converged && within : !converged;
      std::string reason;
      if (!success && c.reachable) reason = converged ? "converged but outside 1 mm / 2 deg" : control::ToString(r.status);
      if (!success && !c.reachable) reason = "unreachable target reported as converged";
      nlohmann::json j = {{"status", control::ToString(r.status)},
                          {"success", success},
                          {"position_error_m", r.position_error_m},
                          {"orientation_error_deg", r.orientation_error_rad * 180.0 / M_PI},
                          {"iterations", r.iterations},
                          {"ipopt_iterations", r.ipopt_iterations},
                          {"rest_cost", r.rest_cost},
                          {"solve_ms", r.solve_ms}};
      if (!reason.empty()) j["failure"] = reason;
      out["configs"][configs[k].first] = j;
    }
    return out;
  };
  ReportIk(request, RunSweep(SweepOptionsFor(request, "ik"), cases, run_case));
  return 0;
}

void ReportIk(const BenchRequest& request, const std::vector<SweepLine>& lines) {
  const auto configs = Configs();
  std::vector<ConfigStats> stats(configs.size());
  int failed = 0;
  for (const SweepLine& line : lines) {
    if (!line.value("ok", false)) {
      ++failed;
      continue;
    }
    const nlohmann::json& r = line["result"];
    const bool reachable = r.at("reachable").get<bool>();
    for (size_t k = 0; k < configs.size(); ++k) {
      const nlohmann::json& j = r.at("configs").at(configs[k].first);
      const bool success = j.at("success").get<bool>();
      ConfigStats& s = stats[k];
      if (reachable) {
        ++s.reachable;
        s.succeeded += success ? 1 : 0;
        s.pos_error_m.push_back(j.at("position_error_m").get<double>());
        s.rot_error_deg.push_back(j.at("orientation_error_deg").get<double>());
        s.solve_ms.push_back(j.at("solve_ms").get<double>());
        s.iterations.push_back(j.at("iterations").get<double>());
        if (success) s.rest_cost.push_back(j.at("rest_cost").get<double>());
      } else {
        ++s.unreachable;
        s.unreachable_reported += success ? 1 : 0;
        s.unreachable_ms.push_back(j.at("solve_ms").get<double>());
      }
    }
  }
  nlohmann::json summary = Summarise(stats[0]);
  summary["protocol"] = "ik";
  summary["seed"] = request.seed;
  summary["shard_index"] = request.shard_index;
  summary["shard_count"] = request.shard_count;
  summary["failed_cases"] = failed;
  summary["success_criterion"] = "status converged, position error <= 1 mm, orientation error <= 2 deg";
  summary["warm_start"] = "home posture (RobotDescription::HomeQ)";
  for (size_t k = 0; k < configs.size(); ++k) summary["configs"][configs[k].first] = Summarise(stats[k]);
  summary["baseline"] = Summarise(stats[1]);
  WriteJson(request.out_dir / "summary.json", summary);
}

}  // namespace toolbench::app
