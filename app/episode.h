#pragma once

#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "app/affordance.h"
#include "app/scene_setup.h"
#include "perception/analysis.h"

namespace toolbench::app {

/// The shipped affordance model: assets/models/affordance_model.json.
std::filesystem::path DefaultAffordanceModelPath();

/// What the episodes of a run share and only read: the scene file, the robot and the tool library
/// (SceneAssets), perception's analyzer of that library (its recogniser and classifier) and the
/// affordance model. Loading them costs ~0.25 s, a twentieth of an episode, the same for every
/// episode: a bench loads them once before its child processes fork, so that each starts with
/// them (EpisodeRequest::resources). Nothing here depends on the seed.
struct EpisodeResources {
  SceneAssets assets;
  std::shared_ptr<const perception::ToolAnalyzer> analyzer;  // ToolAnalyzer(assets.library, DefaultAnalyzerOptions())
  std::filesystem::path affordance_file;                      // as requested
  std::optional<AffordanceModel> affordance;                  // empty when affordance_file does not exist
  double load_ms = 0.0;                                       // wall time of LoadEpisodeResources [ms]
};

struct EpisodeRequest;

/// Loads the resources of `request` (its scene file, user tool folders and affordance model).
/// Throws std::invalid_argument naming the bad input (malformed scene, broken user mesh, a
/// classifier made for another library, an affordance model file that exists but is malformed).
EpisodeResources LoadEpisodeResources(const EpisodeRequest& request);

/// What `toolbench episode` was asked to do.
struct EpisodeRequest {
  SceneRequest scene;             // seed, scene file, tools, cells, user tool folders
  std::string action = "pull";    // the action on the ball: pull, drag-left, drag-right, push
  /// The learned affordance model (toolbench explore) that chooses the tool; when the file does
  /// not exist, or holds no trials of the action, the geometric predictor chooses instead, and
  /// result.json says so (choice_method, choice_note).
  std::filesystem::path affordance_model = DefaultAffordanceModelPath();
  std::filesystem::path out_dir;  // result.json and images go here (created); empty = no files
  bool video = false;             // write video.mp4 from the overview camera
  /// Write overview|side PNGs of the scene after each stage of the tool grasp, the action, the put-down and the ball grasp to
  /// out_dir/frames (for debugging; each costs ~0.2 s).
  bool frames = false;
  bool quiet = false;             // no progress lines, no summary on stdout
  /// Ask for a hand-over of the best-predicted tool when its handle is out of reach (the thesis's
  /// Algorithm 6), instead of grasping the next best tool that is within reach.
  bool best_tool_only = false;
  /// With more than one tool to choose from: each planned tool grasp is checked before anything
  /// moves by planning the action from it (the tool where the grasp plan puts it in the hand,
  /// the arm where the lift ends); a tool with a grasp that leaves no action plan is passed over
  /// for the next in the ranking, and grasped as before only when no other tool passes (the
  /// robot then asks for it again, the re-grip). false: no check (the code before session 22).
  bool check_action_before_grasp = true;
  /// A tool grasp that moved the arm and failed (the tool slipped out, the hand closed on
  /// nothing, the arm was stopped on the way) is followed by a second look at the rack and the
  /// grasp down the new ranking before the robot asks for help. false: help at once (the code
  /// before session 49).
  bool look_again_after_failed_grasp = true;
  bool noise = true;              // sensor noise model on
  /// Loaded for this request's scene file, user tool folders and affordance model (RunEpisode
  /// checks, and throws std::invalid_argument when they were loaded for others); null: RunEpisode
  /// loads them itself (EpisodeResult::resources_ms).
  std::shared_ptr<const EpisodeResources> resources;
};

/// One stage of the episode (thesis Alg. 6).
struct StageRecord {
  std::string name;  // "observe_table", "perceive_tools", "grasp_tool", ...
  bool ok = false;
  std::string outcome;   // short status ("found", "grasped", "unreachable", ...)
  std::string reason;    // why not ok
  double wall_ms = 0.0;  // wall time of the stage [ms]
  double robot_s = 0.0;  // robot (simulated) time the stage took [s]
  /// Physics within the stage: wall time in mj_step [ms], steps, and the mean contacts and
  /// constraint rows per step (what makes a step cost).
  double physics_ms = 0.0;
  long steps = 0;
  double mean_contacts = 0.0;
  double mean_constraint_rows = 0.0;
  double mean_solver_iterations = 0.0;  // constraint solver (+ noslip, when on) iterations per step (PhysicsStats)
  long noslip_steps = 0;                // steps that ran the noslip pass (PhysicsSpec::noslip_scope)
  nlohmann::json details = nlohmann::json::object();
};

/// Everything one episode did and achieved. Perception and control decide from sensors only;
/// the `truth` block and the *_success flags are scored from simulator ground truth afterwards.
struct EpisodeResult {
  std::uint64_t seed = 0;
  std::vector<StageRecord> stages;
  std::string chosen_tool;  // recognised model of the chosen tool ("" when none)
  int chosen_segment = -1;
  bool ball_reachable_at_start = false;   // from perception + IK
  bool assisted = false;                  // a human handed the tool over (hand-over fallback)
  bool grasp_success = false;             // truth: the chosen tool was lifted off the rack in the hand
  bool pull_success = false;              // truth: the ball ended within reach
  bool ball_grasp_success = false;        // truth: the ball was lifted >= 3 cm in the hand
  std::string action = "pull";            // the action performed
  /// How the tool was chosen: "learned" (the affordance model) or "geometric" (fallback)
  std::string choice_method;
  std::string choice_note;                // why the fallback, or which model file
  /// What the choice expected the action to move the ball along its direction [m]: the learned
  /// model's mean over the explored in-hand rolls (the grasp is not planned yet at the choice).
  double predicted_displacement_m = 0.0;
  /// The learned model's expectation once the tool is in the hand, for the actual in-hand pose
  /// [m]; NaN when not learned or the tool was not held.
  double predicted_in_hand_m = std::nan("");
  /// truth: ball displacement along the action's direction (ActionDirection at the ball's start) [m]
  double achieved_displacement_m = 0.0;
  Eigen::Vector2d achieved_displacement_R = Eigen::Vector2d::Zero();  // truth: (dx, dy) in R [m]
  std::string failure;                    // first failed stage: "<stage>: <reason>", empty on success
  /// Wall time of the episode, from composing its scene to its end [s]; the resources shared by a
  /// run's episodes (EpisodeResources) are not in it, see resources_ms.
  double wall_s = 0.0;
  /// Wall time spent loading the EpisodeResources for this episode [ms]; 0 when the request
  /// brought them (a bench loads them once for all its episodes).
  double resources_ms = 0.0;
  /// CPU time of the process over the same span, all its threads [s]: a measure of the work that
  /// other load on a shared machine disturbs less than wall_s.
  double cpu_s = 0.0;
  double robot_s = 0.0;
  nlohmann::json truth = nlohmann::json::object();  // ground truth used for scoring
  /// What perceive_tools saw of the rack (empty when the stage did not run): for benchmarks that
  /// score perception inside the episode (table53 --episodes). Not part of EpisodeJson.
  perception::FrameAnalysis analysis;
};

/// Runs one episode (thesis Alg. 6): observation pose on the table, ball detection, reachable?
/// grasp it : turn to the rack, perceive every tool, choose the best one for the action, grasp
/// its handle (hand-over when it is out of reach, recorded as assisted), pull the ball, put the
/// tool down, look again and grasp the ball when it is in reach. Writes result.json and images
/// to request.out_dir when set. Throws std::invalid_argument for bad input (unknown tool,
/// malformed scene, broken user mesh, unknown action, an affordance model file that exists but is
/// malformed); a stage that fails is a result.
EpisodeResult RunEpisode(const EpisodeRequest& request);

/// A ball seen more than this far below where it would rest on the table top lies on the floor:
/// an action or a put-down swept it off the table, and nothing is left to pull or grasp [m].
inline constexpr double kBallOffTableM = 0.05;

/// How far below where a ball of `radius` would rest on the table top it was seen, at p_RB in R
/// [m] (negative: above it).
double BallBelowTable(const sim::TableSpec& table, double radius, const Eigen::Vector3d& p_RB);

/// The result as JSON (result.json, one results.jsonl line).
nlohmann::json EpisodeJson(const EpisodeResult& result);

/// One screen of plain text for a person.
std::string EpisodeSummary(const EpisodeResult& result);

}  // namespace toolbench::app
