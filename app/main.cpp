// toolbench: the command-line entry point. See README.md for the commands.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "app/bench.h"
#include "app/capture.h"
#include "app/episode.h"
#include "app/explore.h"
#include "app/frame_io.h"
#include "app/perceive.h"
#include "app/scene_setup.h"
#include "app/train_recognizer.h"
#include "common/check.h"
#include "common/paths.h"
#include "common/rng.h"
#include "sim/renderer.h"
#include "toollib/mesh.h"

namespace {

using namespace toolbench;

/// --seed as a non-negative integer (parsed from text: CLI11 would wrap "-3" into a huge number).
void AddSeedOption(CLI::App* cmd, std::uint64_t& seed) {
  cmd->add_option_function<std::string>(
         "--seed",
         [&seed](const std::string& text) {
           if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos) {
             throw CLI::ValidationError("--seed", "must be a non-negative integer, got '" + text + "'");
           }
           try {
             seed = std::stoull(text);
           } catch (const std::exception&) {
             throw CLI::ValidationError("--seed", "out of range: '" + text + "'");
           }
         },
         "Seed of every random draw (a non-negative integer)")
      ->default_str(std::to_string(seed));
}

/// Options shared by every command that builds a scene.
void AddSceneOptions(CLI::App* cmd, app::SceneRequest& request) {
  AddSeedOption(cmd, request.seed);
  cmd->add_option("--scene", request.scene_file, "Scene file (JSON); default: scenes/default.json in the source tree")
      ->check(CLI::ExistingFile);
  cmd->add_option("--tools", request.tools,
                  "Tool models to put on the rack, comma-separated (default: 1-3 drawn from the seed)")
      ->delimiter(',');
  cmd->add_option("--cells", request.cells,
                  "Table 5.3 cell of each tool: pos1 pos2 pos3 rot0 rot1 rot2 rot3 (default: "
                  "pos1, pos2, pos3 in order; pos2 for one tool)")
      ->delimiter(',')
      ->check(CLI::IsMember({"pos1", "pos2", "pos3", "rot0", "rot1", "rot2", "rot3"}));
  cmd->add_option("--tool-dir", request.extra_tool_dirs,
                  "Extra folder of user tools (STL/OBJ/PLY mesh + JSON sidecar); repeatable")
      ->check(CLI::ExistingDirectory);
}

int RunRender(const app::SceneRequest& request, const std::filesystem::path& out_dir,
              const app::CaptureOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  sim::GlContext gl;
  const app::Capture capture = app::CaptureFrame(request, options, gl);
  app::WriteFrame(out_dir, capture.frame, app::CaptureMetadata(capture, request, options));
  WriteTextFile(out_dir / "ground_truth.json", app::GroundTruthJson(capture).dump(2) + "\n");
  WriteTextFile(out_dir / "scene.xml", capture.scene.composed.mjcf);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  spdlog::info("render: seed {}, {} tool(s), frame written to {} ({:.2f} s)", request.seed,
               capture.scene.composed.tools.size(), out_dir.string(), seconds);
  std::cout << out_dir.string() << "\n";
  return 0;
}

int RunScene(const app::SceneRequest& request, const std::filesystem::path& save) {
  const app::LoadedScene scene = app::LoadScene(request);
  // Compile it once so that what we write is known to load.
  sim::World world(scene.composed.mjcf, "scene seed " + std::to_string(request.seed));
  WriteTextFile(save, scene.composed.mjcf);
  for (const auto& placed : scene.composed.tools) {
    spdlog::info("scene: {} at {}", placed.name, placed.cell);
  }
  std::cout << save.string() << "\n";
  return 0;
}

int RunToolsList(const std::vector<std::filesystem::path>& dirs, const std::filesystem::path& scene_file,
                 const std::filesystem::path& write_segmentations) {
  const sim::SceneSpec spec = sim::LoadSceneSpec(scene_file.empty() ? sim::DefaultScenePath() : scene_file);
  const auto library = app::LoadLibraries(spec, dirs);
  if (!write_segmentations.empty()) {
    app::WriteLibrarySegmentations(library, write_segmentations);
    return 0;
  }
  std::printf("%-14s %-8s %7s %7s %9s %6s %6s\n", "name", "family", "length", "mass", "handle_d", "faces", "parts");
  for (const auto& tool : library) {
    std::printf("%-14s %-8s %6.3fm %5.3fkg %7.1fmm %6ld %6zu\n", tool.name.c_str(), tool.family.c_str(),
                tool.total_length, tool.mass, 2000.0 * tool.handle.radius, static_cast<long>(tool.mesh.faces.cols()),
                tool.collision.size());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App cli{
      "toolbench: a digital twin of the iCub choosing and using tools (MuJoCo, headless).\n"
      "Every command is deterministic for a given --seed."};
  cli.require_subcommand(1);
  std::string log_level = "info";
  cli.add_option("--log-level", log_level, "Log level: trace debug info warn error off")
      ->check(CLI::IsMember({"trace", "debug", "info", "warn", "error", "off"}))
      ->capture_default_str();

  app::EpisodeRequest episode_request;
  CLI::App* episode = cli.add_subcommand(
      "episode",
      "One full episode (thesis Alg. 6), the default job: look at the table, find the ball; if it is out of "
      "reach turn to the rack, perceive every tool, choose one, grasp its handle (hand-over when out of reach, "
      "recorded as assisted), pull the ball, put the tool down, grasp the ball. Writes result.json, table.png, "
      "rack.png (and video.mp4 with --video) to --out, a summary on stdout");
  AddSceneOptions(episode, episode_request.scene);
  episode
      ->add_option("--action", episode_request.action,
                   "Action on the ball: pull (toward the robot), drag-left, drag-right (across, to the robot's "
                   "left/right) or push (away); the tool is chosen for it")
      ->check(CLI::IsMember({"pull", "drag-left", "drag-right", "push"}))
      ->capture_default_str();
  episode
      ->add_option("--affordance-model", episode_request.affordance_model,
                   "Learned affordance model that chooses the tool (toolbench explore); when the file does not "
                   "exist or has no trials of --action, the geometric predictor chooses, and result.json says so")
      ->capture_default_str();
  episode->add_option("--out", episode_request.out_dir, "Output folder (default: runs/episode-seed<N>)");
  episode->add_flag("--video", episode_request.video, "Write video.mp4 from the overview camera (slower)");
  episode->add_flag("--frames", episode_request.frames,
                    "Write overview, side-view and rack close-up PNGs after each stage of the tool grasp and the action to "
                    "--out/frames (debugging)");
  episode->add_flag("--quiet", episode_request.quiet, "No progress lines and no summary (for scripts)");
  episode->add_flag("--best-tool-only", episode_request.best_tool_only,
                    "Ask for a hand-over of the best-predicted tool when its handle is out of reach (thesis Alg. 6) "
                    "instead of grasping the next best tool within reach");
  episode->add_flag(
      "--no-action-check", [&](std::int64_t) { episode_request.check_action_before_grasp = false; },
      "Grasp the chosen tool without first planning the action from the planned grasp (with other tools on the "
      "rack, a tool whose grasp leaves no action plan is otherwise passed over for the next one)");
  episode->add_flag(
      "--no-look-again", [&](std::int64_t) { episode_request.look_again_after_failed_grasp = false; },
      "Ask for a hand-over as soon as the robot's own tool grasp fails, without looking at the rack again and "
      "grasping down the new ranking first");
  episode->add_flag(
      "--no-noise", [&](std::int64_t) { episode_request.noise = false; },
      "Ideal images: switch the sensor noise model off");

  app::SceneRequest render_request;
  std::filesystem::path render_out;
  bool no_noise = false;
  std::string look = "rack";
  std::string camera = "helmet";
  CLI::App* render =
      cli.add_subcommand("render",
                         "Compose a scene, turn torso and head to the rack and write one RGB-D frame: "
                         "rgb.png, depth.png (uint16 mm), camera.json (intrinsics, X_RC from encoder FK), "
                         "cloud.ply (root frame), ground_truth.json, scene.xml");
  AddSceneOptions(render, render_request);
  render->add_option("--out", render_out, "Output folder (default: runs/render-seed<N>)");
  render->add_flag("--no-noise", no_noise, "Ideal images: switch the sensor noise model off");
  render->add_option("--look", look, "What to look at: rack or table")
      ->check(CLI::IsMember({"rack", "table"}))
      ->capture_default_str();
  render
      ->add_option("--camera", camera,
                   "helmet (the robot's RGB-D sensor) or overview (a fixed third-person view "
                   "for looking at the scene) or side (from the robot's left, across the table) or rack_close "
                   "(a close-up of the rack, along its ledge)")
      ->check(CLI::IsMember({"helmet", "overview", "side", "rack_close"}))
      ->capture_default_str();

  app::SceneRequest perceive_request;
  std::filesystem::path perceive_out;
  bool perceive_no_noise = false;
  CLI::App* perceive = cli.add_subcommand(
      "perceive",
      "Capture a frame of the rack (as render) and run the episode's perception pipeline on it, writing every "
      "step: analysis.json (one full tool analysis per segment), segments.png, mask_<i>.png, roi_<i>.png, "
      "tool_<i>_fit.ply, tool_<i>_parts.ply, tool_<i>_superquadrics.ply, handles.png, and the score against "
      "ground truth (score.json)");
  AddSceneOptions(perceive, perceive_request);
  perceive->add_option("--out", perceive_out, "Output folder (default: runs/perceive-seed<N>)");
  perceive->add_flag("--no-noise", perceive_no_noise, "Ideal images: switch the sensor noise model off");
  std::filesystem::path perceive_classifier = app::DefaultClassifierPath();
  bool perceive_no_classifier = false;
  bool perceive_user_tools_unknown = false;
  perceive->add_option("--classifier", perceive_classifier, "Tool classifier file (toolbench train-recognizer)")
      ->capture_default_str();
  perceive->add_flag("--no-classifier", perceive_no_classifier,
                     "Recognise without the classifier: extent pre-selection and fit scores only");
  perceive->add_flag("--user-tools-unknown", perceive_user_tools_unknown,
                     "Put the --tool-dir tools on the rack but keep them out of perception's library: they are "
                     "analysed as unknown tools from their clouds");

  app::TrainRecognizerRequest train_request;
  CLI::App* train = cli.add_subcommand(
      "train-recognizer",
      "Render random rack scenes (1-3 tools each, random cells), segment them, label each segment with the "
      "ground-truth tool it shows, train the tool classifier (random forest over pose-invariant features) "
      "and report its accuracy on held-out scenes: dataset.csv, heldout.csv, tool_classifier.yml.gz, "
      "training_report.json. The shipped assets/models/tool_classifier.yml.gz is made with "
      "--seed 1 --scenes 800 --heldout 200 --trees 100");
  AddSeedOption(train, train_request.seed);
  train->add_option("--scenes", train_request.scenes, "Training scenes")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  train
      ->add_option("--heldout", train_request.heldout_scenes,
                   "Held-out scenes, on seeds disjoint from the training ones (0 = scenes/4)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  train->add_option("--trees", train_request.classifier.trees, "Trees in the forest")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  train->add_option("--out", train_request.out_dir, "Output folder")->required();

  app::SceneRequest scene_request;
  std::filesystem::path scene_save;
  CLI::App* scene =
      cli.add_subcommand("scene", "Compose a scene and write its MJCF, which MuJoCo (and its viewer) loads unchanged");
  AddSceneOptions(scene, scene_request);
  scene->add_option("--save", scene_save, "Where to write the MJCF")->required();

  std::vector<std::filesystem::path> list_dirs;
  std::filesystem::path list_scene;
  CLI::App* tools = cli.add_subcommand("tools",
                                       "List the tool library (and check user tools: each mesh must be watertight, "
                                       "outward-oriented, in metres)");
  tools->add_option("--tool-dir", list_dirs, "Extra folder of user tools; repeatable")->check(CLI::ExistingDirectory);
  tools->add_option("--scene", list_scene, "Scene file naming the library folders")->check(CLI::ExistingFile);
  std::filesystem::path write_segmentations;
  tools->add_option("--write-segmentations", write_segmentations,
                    "Segment every tool's shape anew and write the segmentations to this file instead of listing "
                    "(what assets/models/library_segmentation.json is made with; see assets/models/README.md)");

  app::BenchRequest bench_request;
  std::string shard = "0/1";
  CLI::App* bench = cli.add_subcommand("bench",
                                       "Run a benchmark protocol; writes summary.json (and per-case results) to --out. "
                                       "Failed cases are recorded with their reason, never dropped");
  {
    std::string protocols;
    std::vector<std::string> names;
    for (const auto& p : app::BenchProtocols()) {
      protocols += "\n  " + p.name + ": " + p.description;
      names.push_back(p.name);
    }
    bench->add_option("--protocol", bench_request.protocol, "Protocol to run:" + protocols)->required();
    bench->add_option("--out", bench_request.out_dir, "Output folder")->required();
    AddSeedOption(bench, bench_request.seed);
    bench->add_option("--scene", bench_request.scene_file, "Scene file (JSON) of every case; default: scenes/default.json in the source tree")
        ->check(CLI::ExistingFile);
    bench->add_option("--shard", shard, "Run slice i of N (i/N, 0-based); merge the results afterwards")
        ->capture_default_str();
    bench->add_option("--limit", bench_request.limit, "Run at most this many cases (0 = all)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    bench->add_option("--filter", bench_request.filter,
                      "Only cases whose id matches this regular expression (ids: 'hoe_1/rot2' for table53 and "
                      "grasp-gt, 'hoe_1/rot0' pull-gt, 'episode/7' random, 'reachable/12' ik)");
    bench
        ->add_option("--episodes", bench_request.episodes,
                     "random: how many episodes (default 50); table53: run N full episodes per cell (perception "
                     "score + grasp outcome) instead of single frames")
        ->check(CLI::PositiveNumber);
    bench->add_flag("--extended", bench_request.extended,
                    "table53: all 3 places x 4 rotations (12 cells, pos<i>_rot<j>) instead of the thesis's 7");
    bench
        ->add_option("--case-timeout", bench_request.case_timeout_s,
                     "Kill a case running longer than this and record it as failed [s]")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    bench->add_option("--jobs", bench_request.jobs, "Cases run at once, each in its own process")
        ->check(CLI::PositiveNumber)
        ->capture_default_str();
    bench->add_flag("--resume", bench_request.resume, "Keep --out/results.jsonl and skip the cases it already holds");
    bench->add_flag(
        "--no-isolate", [&](std::int64_t) { bench_request.isolate = false; },
        "Run cases in this process instead of child processes (for a debugger)");
    bench->add_flag("--frames", bench_request.frames,
                    "Write overview PNGs of each case's stages to --out/frames (grasp-gt, pull-gt), each "
                    "episode's images to --out/episodes (table53 --episodes), or each random episode's "
                    "grasp and action stages to --out/episodes/N/frames (random)");
    bench->add_flag("--best-tool-only", bench_request.best_tool_only,
                    "random: episodes ask for a hand-over of the best-predicted tool when its "
                    "handle is out of reach instead of grasping the next best tool within reach");
    bench->add_flag(
        "--no-action-check", [&](std::int64_t) { bench_request.check_action_before_grasp = false; },
        "random: episodes grasp the chosen tool without first planning the action from the planned grasp");
    bench->add_flag(
        "--no-look-again", [&](std::int64_t) { bench_request.look_again_after_failed_grasp = false; },
        "random: episodes ask for a hand-over as soon as the own tool grasp fails, without looking at the rack again");
    bench->add_flag("--from-rack-look", bench_request.from_rack_look,
                    "grasp-gt: grasp as the episode does, after the look at the rack (torso turned, hand "
                    "hanging beside the hip) instead of from the home posture");
    bench->add_flag("--hindsight", bench_request.hindsight,
                    "random: also pull with every tool of each episode's rack from its ground-truth handle "
                    "and score the choice against the best in hindsight (about 10 s more per tool)");
  }

  app::ExploreRequest explore_request;
  CLI::App* explore = cli.add_subcommand(
      "explore",
      "Learn tool affordances by exploration in the twin: every library tool (--tools) is handed to the robot "
      "held at each --orientations roll about the handle, the robot performs each --actions on the ball "
      "(--balls positions), and the ball's displacement is recorded (results.jsonl, one line per trial; "
      "--resume continues a run). Then trains the affordance regressor (a Gaussian process per action on "
      "perception's shape features and the in-hand pose) into affordance_model.json and evaluates it on "
      "held-out families and tools against always predicting the mean (evaluation.json, printed). The "
      "shipped assets/models/affordance_model.json: see assets/models/README.md");
  AddSeedOption(explore, explore_request.seed);
  explore->add_option("--out", explore_request.out_dir, "Output folder")->required();
  explore->add_option("--tools", explore_request.tools, "Only library tools whose name matches this regex");
  explore->add_option("--actions", explore_request.actions, "Actions to explore, comma-separated")
      ->delimiter(',')
      ->check(CLI::IsMember({"pull", "drag-left", "drag-right", "push"}))
      ->capture_default_str();
  explore
      ->add_option("--orientations", explore_request.orientations_deg,
                   "Rolls of the tool about the hand's grasp axis [deg], comma-separated: 0 = working side toward "
                   "the fingertips, 90 the back of the hand, 180 the wrist, 270 the palm")
      ->delimiter(',')
      ->capture_default_str();
  explore->add_option("--balls", explore_request.balls, "Ball positions per tool, action and orientation")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  explore->add_option("--jobs", explore_request.jobs, "Trials run at once, each in its own process")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  explore->add_flag("--resume", explore_request.resume, "Keep --out/results.jsonl and skip the trials it holds");
  explore->add_option("--limit", explore_request.limit, "Run at most this many trials (0 = all)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  explore
      ->add_option("--case-timeout", explore_request.case_timeout_s,
                   "Kill a trial running longer than this and record it as failed [s]")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  explore->add_flag("--train-only", explore_request.train_only,
                    "Run no trial: train and evaluate from --out/results.jsonl (its trials of the selected tools "
                    "and actions)");
  explore->add_flag(
      "--no-isolate", [&](std::int64_t) { explore_request.isolate = false; },
      "Run trials in this process instead of child processes (for a debugger)");

  std::vector<std::filesystem::path> merge_dirs;
  std::filesystem::path merge_out;
  CLI::App* merge = cli.add_subcommand(
      "merge", "Join the results.jsonl of several bench run folders (e.g. shards) and write the protocol's report");
  merge->add_option("dirs", merge_dirs, "Run folders of one protocol")->required()->check(CLI::ExistingDirectory);
  merge->add_option("--out", merge_out, "Output folder of the merged report")->required();

  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e);
  }
  spdlog::set_default_logger(spdlog::stderr_color_mt("toolbench"));
  spdlog::set_level(spdlog::level::from_str(log_level));
  try {
    if (render->parsed()) {
      if (render_out.empty()) render_out = "runs/render-seed" + std::to_string(render_request.seed);
      app::CaptureOptions options;
      options.noise = !no_noise;
      options.look_at_table = look == "table";
      options.camera = camera;
      return RunRender(render_request, render_out, options);
    }
    if (scene->parsed()) return RunScene(scene_request, scene_save);
    if (episode->parsed()) {
      if (episode_request.out_dir.empty()) {
        episode_request.out_dir = "runs/episode-seed" + std::to_string(episode_request.scene.seed);
      }
      const app::EpisodeResult result = app::RunEpisode(episode_request);
      if (!episode_request.quiet) std::cout << app::EpisodeSummary(result) << episode_request.out_dir.string() << "\n";
      return 0;
    }
    if (perceive->parsed()) {
      if (perceive_out.empty()) perceive_out = "runs/perceive-seed" + std::to_string(perceive_request.seed);
      app::CaptureOptions options;
      options.noise = !perceive_no_noise;
      app::PerceiveOptions perceive_options;
      perceive_options.classifier = perceive_no_classifier ? std::filesystem::path() : perceive_classifier;
      perceive_options.user_tools_unknown = perceive_user_tools_unknown;
      return app::RunPerceive(perceive_request, perceive_out, options, perceive_options);
    }
    if (tools->parsed()) return RunToolsList(list_dirs, list_scene, write_segmentations);
    if (train->parsed()) return app::RunTrainRecognizer(train_request);
    if (explore->parsed()) return app::RunExplore(explore_request);
    if (bench->parsed()) {
      const auto slash = shard.find('/');
      try {
        if (slash == std::string::npos) throw std::invalid_argument("no slash");
        bench_request.shard_index = std::stoi(shard.substr(0, slash));
        bench_request.shard_count = std::stoi(shard.substr(slash + 1));
      } catch (const std::exception&) {
        throw std::invalid_argument("--shard '" + shard + "' is not of the form i/N");
      }
      return app::RunBench(bench_request);
    }
    if (merge->parsed()) return app::MergeRuns(merge_dirs, merge_out);
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
