#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace toolbench::app {

/// What `toolbench explore` was asked to do.
struct ExploreRequest {
  std::uint64_t seed = 1;         // master seed: trial seeds, ball positions
  std::filesystem::path out_dir;  // results.jsonl, affordance_model.json, evaluation.json, ... (created)
  std::string tools;              // ECMAScript regex on library tool names (searched); empty = every tool
  /// Actions explored: "pull", "drag-left", "drag-right", "push" (each at most once).
  std::vector<std::string> actions{"pull", "drag-left", "drag-right", "push"};
  /// Rolls of the tool about the hand's grasp axis [deg], each in [0, 360): 0 = the tool's
  /// working side (+x_T) along x_G (toward the fingertips), 90 = toward the back of the hand,
  /// 180 = toward the wrist, 270 = toward the palm.
  std::vector<double> orientations_deg{0.0, 90.0, 180.0, 270.0};
  int balls = 1;                  // ball positions per tool, action and orientation, >= 1
  int jobs = 1;                   // trials at once, each in its own process, >= 1
  bool resume = false;            // keep out_dir/results.jsonl and skip the trials it holds
  int limit = 0;                  // at most this many trials (0 = all), for quick looks
  double case_timeout_s = 300.0;  // a trial running longer is killed and recorded [s], > 0
  bool isolate = true;            // false: trials in this process (for a debugger)
  /// Run no trial: train and evaluate from out_dir/results.jsonl (the trials of the selected
  /// tools and actions that it holds).
  bool train_only = false;
  void Validate() const;          // throws std::invalid_argument naming the field and its value
};

/// `toolbench explore`: affordance learning by exploration in the twin, as the original
/// tool-affordance work did. Trials = library tools (matching `tools`) x actions x in-hand
/// orientations x ball positions; each trial composes a scene with the tool on the rack and the
/// ball out of reach on the table (drawn from the scene's ball range and the trial seed), hands
/// the tool to the robot held by its handle at the trial's roll (control::HandOver; the person's
/// part is the recorded teleport), performs the action with the pull skill on the ball's position,
/// and measures from simulator ground truth (the supervisor) where the ball went. The regressor's
/// inputs come from perception: the library model's shape analysis (the same cached analysis
/// the episode uses for a recognised tool) and the known in-hand pose; see AffordanceFeatures.
/// Trials run through RunSweep (child processes, resume); results.jsonl gets one line per
/// trial. Then the labelled trials train the AffordanceModel (out_dir/affordance_model.json,
/// identical bytes for the same seed and options) and leave-one-family-out and leave-one-tool-out
/// evaluations against the mean predictor are written to out_dir/evaluation.json and printed.
/// Returns 0 when the run completed (failed trials are recorded, not fatal); throws
/// std::invalid_argument for bad requests (unknown action, a regex matching no tool, ...).
int RunExplore(const ExploreRequest& request);

/// Trains and evaluates from an exploration's results.jsonl without running trials, on the
/// labelled trials of `tools` and `actions` (empty = all): writes affordance_model.json and
/// evaluation.json into out_dir and returns the evaluation JSON. `info` goes into the model's
/// provenance. Throws std::invalid_argument for a missing or malformed file or fewer than 2
/// labelled trials.
nlohmann::json TrainFromExploration(const std::filesystem::path& results_jsonl, const std::filesystem::path& out_dir,
                                    const nlohmann::json& info, const std::vector<std::string>& tools = {},
                                    const std::vector<std::string>& actions = {});

}  // namespace toolbench::app
