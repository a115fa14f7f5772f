#include "app/bench_ik.h"

#include <cmath>
#include <fstream>
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

}  // namespace

int RunIkBench(const BenchRequest& request) {
  const robot::RobotDescription robot = robot::LoadRobotDescription(robot::DefaultRobotSidecar());
  const control::KinematicChain chain = control::MakeRightArmChain(robot.model, robot.palm_frame);
  const Eigen::VectorXd q_home = robot.HomeQ();

  struct Config {
    std::string name;
    control::IkOptions options;
  };
  std::vector<Config> configs(3);
  configs[0].name = "default";  // pre-solve + rest refinement, Ipopt only when that fails
  configs[1].name = "baseline_plain_ipopt";  // thesis / iKin-like: Ipopt from the warm start
  configs[1].options.presolve = false;
  configs[2].name = "presolve_then_ipopt_polish";  // Ipopt after every pre-solve
  configs[2].options.polish = true;
  std::vector<control::CartesianSolver> solvers;
  for (const Config& config : configs) solvers.emplace_back(chain, q_home, config.options);
  std::vector<ConfigStats> stats(configs.size());

  std::filesystem::create_directories(request.out_dir);
  std::ofstream cases(request.out_dir / "cases.jsonl");
  if (!cases) ThrowInvalid("bench ik: cannot write ", (request.out_dir / "cases.jsonl").string());
  int run = 0;
  for (int index = 0; index < kReachableCases + kUnreachableCases; ++index) {
    if (!InShard(request, index)) continue;
    if (request.limit > 0 && run >= request.limit) break;
    ++run;
    const IkCase c = MakeCase(request, chain, q_home, index);
    for (size_t k = 0; k < configs.size(); ++k) {
      const control::IkResult r = solvers[k].Solve(c.X_RT, q_home);
      const bool within = r.position_error_m <= kSuccessPosM && r.orientation_error_rad <= kSuccessRotRad;
      const bool success = r.status == control::IkStatus::kConverged && within;
      ConfigStats& s = stats[k];
      std::string reason;
      if (c.reachable) {
        ++s.reachable;
        s.succeeded += success ? 1 : 0;
        s.pos_error_m.push_back(r.position_error_m);
        s.rot_error_deg.push_back(r.orientation_error_rad * 180.0 / M_PI);
        s.solve_ms.push_back(r.solve_ms);
        s.iterations.push_back(r.iterations);
        if (success) s.rest_cost.push_back(r.rest_cost);
        if (!success) {
          reason = r.status != control::IkStatus::kConverged ? control::ToString(r.status)
                                                             : "converged but outside 1 mm / 2 deg";
        }
      } else {
        ++s.unreachable;
        const bool reported = r.status != control::IkStatus::kConverged;
        s.unreachable_reported += reported ? 1 : 0;
        s.unreachable_ms.push_back(r.solve_ms);
        if (!reported) reason = "unreachable target reported as converged";
      }
      const Eigen::Vector3d p = c.X_RT.translation();
      nlohmann::json line = {{"index", index},
                             {"config", configs[k].name},
                             {"reachable", c.reachable},
                             {"target_p_R", {p.x(), p.y(), p.z()}},
                             {"status", control::ToString(r.status)},
                             {"success", c.reachable ? success : !(r.status == control::IkStatus::kConverged)},
                             {"position_error_m", r.position_error_m},
                             {"orientation_error_deg", r.orientation_error_rad * 180.0 / M_PI},
                             {"iterations", r.iterations},
                             {"ipopt_iterations", r.ipopt_iterations},
                             {"rest_cost", r.rest_cost},
                             {"solve_ms", r.solve_ms}};
      if (!reason.empty()) line["failure"] = reason;
      cases << line.dump() << "\n";
    }
  }
  nlohmann::json summary = Summarise(stats[0]);
  summary["protocol"] = "ik";
  summary["seed"] = request.seed;
  summary["shard_index"] = request.shard_index;
  summary["shard_count"] = request.shard_count;
  summary["success_criterion"] = "status converged, position error <= 1 mm, orientation error <= 2 deg";
  summary["warm_start"] = "home posture (RobotDescription::HomeQ)";
  for (size_t k = 0; k < configs.size(); ++k) summary["configs"][configs[k].name] = Summarise(stats[k]);
  summary["baseline"] = Summarise(stats[1]);
  WriteJson(request.out_dir / "summary.json", summary);
  return 0;
}

}  // namespace toolbench::app
