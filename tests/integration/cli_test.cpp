// The command line: bad input gives a clear message and a non-zero exit, never a crash.
#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>
#include "common/paths.h"
#include "sim/scene_spec.h"
#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace {

using ::testing::AnyOf;
using ::testing::HasSubstr;

struct CliRun {
  int code;
  std::string output;
};

CliRun Toolbench(const std::string& args) {
  const std::string cmd = std::string(TOOLBENCH_EXE) + " " + args + " 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  std::string output;
  std::array<char, 4096> buffer{};
  while (size_t n = fread(buffer.data(), 1, buffer.size(), pipe)) output.append(buffer.data(), n);
  const int status = pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status), output};
}

std::filesystem::path TempDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("toolbench_cli_" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

TEST(CliTest, HelpDescribesCommandsAndDefaults) {
  const CliRun help = Toolbench("--help");
  EXPECT_EQ(help.code, 0);
  EXPECT_THAT(help.output, HasSubstr("render"));
  EXPECT_THAT(help.output, HasSubstr("scene"));
  const CliRun render_help = Toolbench("render --help");
  EXPECT_EQ(render_help.code, 0);
  EXPECT_THAT(render_help.output, HasSubstr("--seed"));
  EXPECT_THAT(render_help.output, HasSubstr("--no-noise"));
}

TEST(CliTest, UnknownToolAndCellAreNamed) {
  const auto dir = TempDir("unknown");
  CliRun r = Toolbench("scene --tools spoon_9 --save " + (dir / "s.xml").string());
  EXPECT_NE(r.code, 0);
  EXPECT_THAT(r.output, HasSubstr("spoon_9"));
  r = Toolbench("scene --tools hoe_1 --cells pos9 --save " + (dir / "s.xml").string());
  EXPECT_NE(r.code, 0);
  EXPECT_THAT(r.output, HasSubstr("pos9"));
  r = Toolbench("render --seed -3");
  EXPECT_NE(r.code, 0);
}

TEST(CliTest, MalformedSceneFileIsNamed) {
  const auto dir = TempDir("scene");
  const auto file = dir / "broken.json";
  FILE* f = std::fopen(file.c_str(), "w");
  std::fputs("{\"rack\": {\"incline_deg\": 90}}", f);
  std::fclose(f);
  const CliRun r = Toolbench("scene --scene " + file.string() + " --save " + (dir / "s.xml").string());
  EXPECT_NE(r.code, 0);
  EXPECT_THAT(r.output, HasSubstr("broken.json"));
  EXPECT_THAT(r.output, HasSubstr("incline_deg"));
}

TEST(CliTest, BrokenUserMeshIsNamed) {
  const auto dir = TempDir("mesh");
  FILE* f = std::fopen((dir / "bad.stl").c_str(), "w");
  std::fputs("solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n", f);  // truncated
  std::fclose(f);
  f = std::fopen((dir / "bad.json").c_str(), "w");
  std::fputs(R"({"name": "bad", "family": "custom", "mesh": "bad.stl", "mass": 0.2,
    "handle": {"center": [0,0,0.1], "axis": [0,0,1], "length": 0.1, "radius": 0.015},
    "effector": {"center": [0,0,0.3], "axis": [0,0,1], "length": 0.1, "radius": 0.02},
    "symmetries": [], "params": {}, "total_length": 0.4})", f);
  std::fclose(f);
  const CliRun r = Toolbench("tools --tool-dir " + dir.string());
  EXPECT_NE(r.code, 0);
  EXPECT_THAT(r.output, HasSubstr("bad.stl"));
}

TEST(CliTest, SceneWritesLoadableMjcf) {
  const auto dir = TempDir("save");
  const CliRun r = Toolbench("scene --seed 4 --save " + (dir / "scene.xml").string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::file_size(dir / "scene.xml") > 1000);
}

TEST(CliTest, RenderWritesTheFrameFiles) {
  const auto dir = TempDir("render");
  const CliRun r = Toolbench("render --seed 1 --out " + dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* file : {"rgb.png", "depth.png", "camera.json", "cloud.ply", "ground_truth.json", "scene.xml"}) {
    EXPECT_TRUE(std::filesystem::exists(dir / file)) << file;
  }
}

std::string ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(CliTest, PerceiveWritesEveryStep) {
  const auto dir = TempDir("perceive");
  const CliRun r = Toolbench("perceive --seed 1 --out " + dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* file : {"rgb.png", "depth.png", "camera.json", "cloud.ply", "ground_truth.json", "analysis.json",
                           "segments.png", "handles.png", "score.json"}) {
    EXPECT_TRUE(std::filesystem::exists(dir / file)) << file;
  }
  const nlohmann::json analysis = nlohmann::json::parse(ReadFile(dir / "analysis.json"));
  ASSERT_FALSE(analysis["tools"].empty()) << analysis.dump(2);
  int analysed = 0;
  for (size_t i = 0; i < analysis["tools"].size(); ++i) {
    const nlohmann::json& tool = analysis["tools"][i];
    for (const char* key : {"status", "reason", "segment", "roi", "model", "known", "confidence", "X_RT", "fit_error_m",
                            "parts", "handle", "features", "ms", "cloud", "candidates", "files"}) {
      EXPECT_TRUE(tool.contains(key)) << "tool " << i << " lacks " << key;
    }
    const std::string n = std::to_string(i);
    EXPECT_TRUE(std::filesystem::exists(dir / ("mask_" + n + ".png"))) << n;
    EXPECT_TRUE(std::filesystem::exists(dir / ("roi_" + n + ".png"))) << n;
    for (const auto& file : tool["files"]) {
      EXPECT_GT(std::filesystem::file_size(dir / file.get<std::string>()), 100u) << file;
    }
    if (tool["status"] != "ok") continue;
    ++analysed;
    for (const char* key : {"center_R", "axis_R", "radius_m", "length_m", "X_RH"}) {
      EXPECT_TRUE(tool["handle"].contains(key)) << key;
    }
    ASSERT_FALSE(tool["parts"].empty());
    for (const char* key : {"size_m", "e1", "e2", "X_RS"}) {
      EXPECT_TRUE(tool["parts"][0]["superquadric"].contains(key)) << key;
    }
    for (const char* key : {"segmentation", "cloud", "classification", "recognition", "shape", "total"}) {
      EXPECT_TRUE(tool["ms"].contains(key)) << key;
    }
    EXPECT_THAT(ReadFile(dir / ("tool_" + n + "_fit.ply")), HasSubstr("element vertex"));
    EXPECT_THAT(ReadFile(dir / ("tool_" + n + "_parts.ply")), HasSubstr("element vertex"));
    EXPECT_THAT(ReadFile(dir / ("tool_" + n + "_superquadrics.ply")), HasSubstr("element face"));
  }
  EXPECT_GT(analysed, 0);
  const nlohmann::json score = nlohmann::json::parse(ReadFile(dir / "score.json"));
  ASSERT_FALSE(score["tools"].empty());
  EXPECT_TRUE(score["tools"][0].contains("verdict"));
  EXPECT_TRUE(score.contains("mean_score"));
}

TEST(CliTest, PerceiveBadInputIsNamed) {
  CliRun r = Toolbench("perceive --user-tools-unknown --out " + TempDir("perceive_bad").string());
  EXPECT_NE(r.code, 0);
  EXPECT_THAT(r.output, HasSubstr("--tool-dir"));
  r = Toolbench("perceive --classifier /nonexistent/c.yml.gz --out " + TempDir("perceive_bad2").string());
  EXPECT_NE(r.code, 0);
  EXPECT_THAT(r.output, HasSubstr("/nonexistent/c.yml.gz"));
}

TEST(CliTest, BenchRunsItsCasesInTheSceneGiven) {
  // The default scene with the rack moved 3 m to the robot's right: no handle is within reach.
  const auto dir = TempDir("bench_scene");
  std::ifstream default_scene(toolbench::sim::DefaultScenePath());
  nlohmann::json scene = nlohmann::json::parse(default_scene);
  scene["name"] = "far_rack";
  scene["rack"]["origin"][1] = 3.0;
  std::ofstream(dir / "far_rack.json") << scene.dump(1);
  const std::string common = "bench --protocol grasp-gt --filter '^stick_1/pos2$' ";
  const CliRun near = Toolbench(common + "--out " + (dir / "near").string());
  ASSERT_EQ(near.code, 0) << near.output;
  const CliRun far = Toolbench(common + "--scene " + (dir / "far_rack.json").string() + " --out " + (dir / "far").string());
  ASSERT_EQ(far.code, 0) << far.output;
  auto first_result = [](const std::filesystem::path& run) {
    std::ifstream in(run / "results.jsonl");
    std::string line;
    std::getline(in, line);
    return nlohmann::json::parse(line)["result"];
  };
  EXPECT_EQ(first_result(dir / "near")["grasp_status"], "grasped");
  EXPECT_EQ(first_result(dir / "far")["grasp_status"], "unreachable");
  std::ifstream info(dir / "far" / "run.json");
  EXPECT_EQ(nlohmann::json::parse(info)["scene"], (dir / "far_rack.json").string());
  const CliRun missing = Toolbench(common + "--scene " + (dir / "no_such_scene.json").string() + " --out " +
                                   (dir / "missing").string());
  EXPECT_NE(missing.code, 0);
  EXPECT_THAT(missing.output, HasSubstr("no_such_scene.json"));
}

TEST(CliTest, Table53BenchScoresCasesAndWritesTheReport) {
  const auto dir = TempDir("table53");
  // Two cases of the sweep (hammer_1 in pos1 and pos2), ours and the thesis configuration.
  const CliRun r = Toolbench("bench --protocol table53 --limit 2 --out " + dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  std::ifstream in(dir / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(in);
  EXPECT_EQ(summary["cases"], 2);
  EXPECT_EQ(summary["failed_cases"], 0);
  for (const char* key : {"mean_score", "share_perfect", "share_zero", "recognition_accuracy",
                          "handle_error_median_m", "handle_error_p90_m", "per_stage_ms_median"}) {
    EXPECT_TRUE(summary.contains(key)) << key;
    EXPECT_TRUE(summary["thesis_config"].contains(key)) << key;
  }
  EXPECT_GE(summary["mean_score"].get<double>(), 0.0);
  EXPECT_LE(summary["mean_score"].get<double>(), 1.0);
  // The handle is found within a few centimetres on these easy, upright cells.
  EXPECT_LT(summary["handle_error_median_m"].get<double>(), 0.03);
  std::ifstream table(dir / "table53.md");
  const std::string md((std::istreambuf_iterator<char>(table)), std::istreambuf_iterator<char>());
  EXPECT_THAT(md, HasSubstr("| tool name | pos1 | pos2 | pos3 | rot0 | rot1 | rot2 | rot3 | overall |"));
  EXPECT_THAT(md, HasSubstr("| hammer_1 |"));
  // One results line per case, and merging the folder reproduces the report.
  std::ifstream results(dir / "results.jsonl");
  int lines = 0;
  for (std::string line; std::getline(results, line);) ++lines;
  EXPECT_EQ(lines, 2);
  const auto merged = TempDir("table53_merged");
  const CliRun m = Toolbench("merge " + dir.string() + " --out " + merged.string());
  ASSERT_EQ(m.code, 0) << m.output;
  EXPECT_TRUE(std::filesystem::exists(merged / "table53.md"));
}

TEST(CliTest, EpisodeRunsEveryStageAndWritesAValidResult) {
  const auto dir = TempDir("episode");
  const CliRun r = Toolbench("episode --seed 1 --out " + dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("episode seed 1"));
  std::ifstream in(dir / "result.json");
  const nlohmann::json result = nlohmann::json::parse(in);
  for (const char* key : {"grasp_success", "pull_success", "ball_grasp_success", "assisted", "chosen_tool",
                          "predicted_displacement_m", "achieved_displacement_m", "stages", "wall_s", "resources_ms",
                          "cpu_s", "truth"}) {
    EXPECT_TRUE(result.contains(key)) << key;
  }
  // The default scene runs the noslip pass only while a tool rests on the rack awake: in the grasp
  // (the tools beside the grasped one wake), never in the ball's grasp, when the hand is far from
  // the rack. (Not checked in the put-down: since session 50's slower drag seed 1 keeps its hoe
  // through the pull, and 28 steps of its put-down run the pass: the arm rises from it by the rack,
  // and `--frames` shows the hand beside lstick_2 there.)
  std::vector<std::string> stages;
  long steps = 0, noslip = 0;
  for (const auto& s : result["stages"]) {
    stages.push_back(s["name"]);
    EXPECT_TRUE(s.contains("wall_ms") && s.contains("ok") && s.contains("outcome")) << s.dump();
    steps += s["steps"].get<long>();
    noslip += s["noslip_steps"].get<long>();
    if (s["name"] == "grasp_tool") {
      EXPECT_GT(s["noslip_steps"].get<long>(), 0);
    }
    if (s["name"] == "grasp_ball") {
      EXPECT_EQ(s["noslip_steps"], 0) << s["name"];
    }
    // A pull that dragged measures how far the tool had turned in the grip since the inspection
    // (seed 1 here: hoe_2, handed back after the look in the hand found none, pulls the ball in).
    if (s["name"] == "pull" && (s["outcome"] == "pulled" || s["outcome"] == "lost_tool")) {
      for (const char* stage : {"above_start", "at_start", "dragged"}) {
        const std::string deg = std::string(stage) + "_error_deg_truth";
        const std::string m = std::string(stage) + "_effector_error_m_truth";
        ASSERT_TRUE(s["details"].contains(deg) && s["details"].contains(m)) << s["details"].dump();
        EXPECT_GE(s["details"][deg].get<double>(), 0.0);
        EXPECT_LT(s["details"][deg].get<double>(), 180.0 + 1e-9);
        EXPECT_GE(s["details"][m].get<double>(), 0.0);
      }
    }
  }
  EXPECT_LT(noslip, steps / 2);
  ASSERT_GE(stages.size(), 2u);
  EXPECT_EQ(stages[0], "observe_table");
  EXPECT_EQ(stages[1], "check_reach");
  // Seed 1's ball starts out of reach: the robot must have turned to the rack and chosen a tool.
  if (!result["ball_reachable_at_start"].get<bool>()) {
    EXPECT_NE(std::find(stages.begin(), stages.end(), "perceive_tools"), stages.end());
    EXPECT_NE(std::find(stages.begin(), stages.end(), "choose_tool"), stages.end());
    EXPECT_FALSE(result["chosen_tool"].get<std::string>().empty());
    // Scored against ground truth: the perception of the tool the robot went for, and whether its
    // grasp was planned (the handle within reach).
    const nlohmann::json& perceived = result["truth"]["chosen_tool_perception"];
    EXPECT_THAT(perceived["score"].get<double>(), AnyOf(0.0, 0.5, 1.0)) << perceived.dump();
    EXPECT_GE(perceived["handle_error_m"].get<double>(), 0.0);
    EXPECT_FALSE(perceived["verdict"].get<std::string>().empty());
    for (const auto& s : result["stages"]) {
      if (s["name"] == "grasp_tool") {
        EXPECT_TRUE(s["details"]["grasp_planned"].is_boolean()) << s["details"].dump();
      }
    }
  }
  EXPECT_TRUE(std::filesystem::exists(dir / "table.png"));
}

// scenes/noslip_always.json runs the noslip pass at every step of the same episode (the default
// scene's is checked in EpisodeRunsEveryStageAndWritesAValidResult).
TEST(CliTest, TheNoslipAlwaysSceneRunsThePassAtEveryStep) {
  const auto dir = TempDir("episode_always");
  const CliRun r = Toolbench("episode --seed 1 --quiet --scene " +
                             (toolbench::ScenesDir() / "noslip_always.json").string() + " --out " + dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  std::ifstream in(dir / "result.json");
  const nlohmann::json stages = nlohmann::json::parse(in)["stages"];
  // (Outcomes are left to the benchmarks: a last bit of another machine's libm can tip a pull.)
  ASSERT_GE(stages.size(), 2u);
  for (const auto& s : stages) {
    EXPECT_EQ(s["noslip_steps"], s["steps"]) << s["name"];
  }
}

// Random episode 2 of seed 1 (bench --protocol random --seed 1): three tools on the rack, and the
// one predicted best (a hook standing upside down, rot2) has its handle out of reach.
constexpr const char* kUnreachableFirstChoiceSeed = "1267194658511675468";

nlohmann::json ReadResult(const std::filesystem::path& dir) {
  std::ifstream in(dir / "result.json");
  return nlohmann::json::parse(in);
}

nlohmann::json Stage(const nlohmann::json& result, const std::string& name) {
  for (const auto& s : result["stages"]) {
    if (s["name"] == name) return s;
  }
  ADD_FAILURE() << "no " << name << " stage in " << result.dump(1);
  return nlohmann::json::object();
}

TEST(CliTest, AnEpisodeTakesTheNextBestToolWhenTheFirstChoiceIsOutOfReach) {
  const auto dir = TempDir("episode_fallback");
  const CliRun r = Toolbench(std::string("episode --quiet --seed ") + kUnreachableFirstChoiceSeed + " --out " +
                             dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json result = ReadResult(dir);
  const nlohmann::json grasp = Stage(result, "grasp_tool");
  const nlohmann::json& tried = grasp["details"]["tools_tried"];
  ASSERT_GE(tried.size(), 2u) << grasp.dump(1);
  // The scene exercises the fallback only while the first choice is out of reach.
  ASSERT_EQ(tried[0]["status"], "unreachable") << tried.dump(1);
  EXPECT_EQ(grasp["details"]["first_choice"], tried[0]["model"]);
  EXPECT_EQ(result["chosen_tool"], tried.back()["model"]);
  EXPECT_NE(result["chosen_tool"], tried[0]["model"]);
  EXPECT_TRUE(result["grasp_success"].get<bool>()) << grasp.dump(1);
  EXPECT_FALSE(result["assisted"].get<bool>());

  // As the thesis does: the best-predicted tool, handed over.
  const auto thesis_dir = TempDir("episode_fallback_thesis");
  const CliRun t = Toolbench(std::string("episode --quiet --best-tool-only --seed ") + kUnreachableFirstChoiceSeed +
                             " --out " + thesis_dir.string());
  ASSERT_EQ(t.code, 0) << t.output;
  const nlohmann::json thesis = ReadResult(thesis_dir);
  const nlohmann::json thesis_grasp = Stage(thesis, "grasp_tool");
  EXPECT_EQ(thesis_grasp["details"]["tools_tried"].size(), 1u);
  EXPECT_EQ(thesis_grasp["outcome"], "handed_over");
  EXPECT_EQ(thesis["chosen_tool"], tried[0]["model"]);
  EXPECT_TRUE(thesis["assisted"].get<bool>());
}

// Random episode 1 of seed 2 (bench --protocol random --seed 2): spatula_1's handle stands
// upside down out of reach (rot2), so spatula_1 at pos1 is chosen; its grip leaves no plan of
// the pull, and neither does the tool as the hand-over gives it: no wrist orientation puts its
// face behind the ball.
constexpr const char* kHandedOverWrongWayRoundSeed = "3661145302818129580";

// The robot asks for the tool turned about its handle's axis and plans the pull again: half a
// turn gives a plan, and the ball comes into reach (before: the pull stopped unplanned).
TEST(CliTest, AnEpisodeAsksForTheToolTurnedWhenTheHandOverLeavesNoPlan) {
  const auto dir = TempDir("episode_turned");
  const CliRun r =
      Toolbench(std::string("episode --quiet --seed ") + kHandedOverWrongWayRoundSeed + " --out " + dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json result = ReadResult(dir);
  const nlohmann::json pull = Stage(result, "pull");
  EXPECT_TRUE(result["assisted"].get<bool>());
  ASSERT_TRUE(pull["details"].contains("regrip_turns")) << pull.dump(1);
  EXPECT_EQ(pull["details"]["regrip_turns"], 1);
  EXPECT_DOUBLE_EQ(pull["details"]["regrip_turn_deg"].get<double>(), 180.0);
  EXPECT_EQ(pull["outcome"], "pulled") << pull["reason"];
  EXPECT_TRUE(result["pull_success"].get<bool>());
}

// Random seed 4, episode 16 (session 50's affordance model): spatula_3, lying on the rack (rot3),
// slips out of the hand after the lift at the pose first seen. The robot looks at the rack again
// and grasps it where it now lies. (Seed 4 episode 39, stick_2, did the same until the model
// remade in session 50 chose other tools there.)
constexpr const char* kDroppedThenLookAgainSeed = "5088544740784365298";

TEST(CliTest, AnEpisodeLooksAtTheRackAgainAfterTheToolSlipsOut) {
  const auto dir = TempDir("episode_look_again");
  const CliRun r =
      Toolbench(std::string("episode --quiet --seed ") + kDroppedThenLookAgainSeed + " --out " + dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json result = ReadResult(dir);
  const nlohmann::json grasp = Stage(result, "grasp_tool");
  EXPECT_EQ(grasp["outcome"], "grasped") << grasp["reason"];
  EXPECT_EQ(grasp["details"]["looks_again"], 1);
  EXPECT_EQ(grasp["details"]["look_again"]["after"], "dropped");
  const nlohmann::json& tried = grasp["details"]["tools_tried"];
  ASSERT_EQ(tried.size(), 2u) << tried.dump(1);
  EXPECT_EQ(tried[0]["look"], 0);
  EXPECT_EQ(tried[0]["status"], "dropped");
  EXPECT_EQ(tried[1]["look"], 1);
  EXPECT_EQ(tried[1]["model"], "spatula_3");
  EXPECT_EQ(tried[1]["status"], "grasped");
  EXPECT_TRUE(result["grasp_success"].get<bool>());
  // The grasp needed no help (the look at the tool in the hand then finds none, and it is
  // re-gripped: the episode is assisted after the grasp).
  EXPECT_FALSE(grasp["details"]["assisted"].get<bool>());
  EXPECT_TRUE(std::filesystem::exists(dir / "rack.png"));
  EXPECT_TRUE(std::filesystem::exists(dir / "rack_again.png"));

  // Without the second look the robot asks for help at once.
  const auto without = TempDir("episode_no_look_again");
  const CliRun n = Toolbench(std::string("episode --quiet --no-look-again --seed ") + kDroppedThenLookAgainSeed +
                             " --out " + without.string());
  ASSERT_EQ(n.code, 0) << n.output;
  const nlohmann::json helped = ReadResult(without);
  const nlohmann::json handed = Stage(helped, "grasp_tool");
  EXPECT_EQ(handed["outcome"], "handed_over");
  EXPECT_EQ(handed["details"]["looks_again"], 0);
  EXPECT_TRUE(handed["details"]["look_again"].is_null());
  EXPECT_FALSE(helped["grasp_success"].get<bool>());
  EXPECT_TRUE(helped["assisted"].get<bool>());
}

// A bench loads the library and the models once, before its child processes fork
// (EpisodeResources); its episode of a seed is the episode `toolbench episode` runs alone.
TEST(CliTest, ABenchEpisodeIsTheEpisodeOfItsSeedRunAlone) {
  const auto bench_dir = TempDir("bench_episode_2");
  const CliRun b = Toolbench("bench --protocol random --episodes 3 --seed 1 --filter '^episode/2$' --out " +
                             bench_dir.string());
  ASSERT_EQ(b.code, 0) << b.output;
  std::ifstream lines(bench_dir / "results.jsonl");
  std::string line;
  ASSERT_TRUE(std::getline(lines, line));
  const nlohmann::json in_bench = nlohmann::json::parse(line)["result"];
  ASSERT_EQ(std::to_string(in_bench["seed"].get<std::uint64_t>()), kUnreachableFirstChoiceSeed);

  const auto dir = TempDir("episode_alone");
  const CliRun r = Toolbench(std::string("episode --seed ") + kUnreachableFirstChoiceSeed + " --out " + dir.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_THAT(r.output, HasSubstr("loading the library and models"));
  const nlohmann::json alone = ReadResult(dir);
  EXPECT_GT(alone["resources_ms"].get<double>(), 0.0);
  EXPECT_EQ(in_bench["resources_ms"].get<double>(), 0.0);
  EXPECT_GT(alone["cpu_s"].get<double>(), 0.0);
  // Bit for bit: the same robot time, the ball where it ended, every stage's outcome.
  EXPECT_EQ(alone["robot_s"], in_bench["robot_s"]);
  EXPECT_EQ(alone["truth"]["ball_end_R"], in_bench["truth"]["ball_end_R"]);
  EXPECT_EQ(alone["chosen_tool"], in_bench["chosen_tool"]);
  ASSERT_EQ(alone["stages"].size(), in_bench["stages"].size());
  for (size_t i = 0; i < alone["stages"].size(); ++i) {
    EXPECT_EQ(alone["stages"][i]["outcome"], in_bench["stages"][i]["outcome"]) << alone["stages"][i]["name"];
  }
}

TEST(CliTest, EpisodeBadInputIsNamed) {
  const CliRun unknown = Toolbench("episode --tools no_such_tool --out " + TempDir("episode_bad").string());
  EXPECT_NE(unknown.code, 0);
  EXPECT_THAT(unknown.output, HasSubstr("no_such_tool"));
  const CliRun action = Toolbench("episode --action throw --out " + TempDir("episode_bad2").string());
  EXPECT_NE(action.code, 0);
  EXPECT_THAT(action.output, HasSubstr("throw"));
  // A known action is accepted; an affordance model that exists but is malformed is named.
  const auto dir = TempDir("episode_bad3");
  std::ofstream(dir / "model.json") << "{\"format\": \"other\"}";
  const CliRun model = Toolbench("episode --action push --affordance-model " + (dir / "model.json").string() +
                                 " --out " + dir.string());
  EXPECT_NE(model.code, 0);
  EXPECT_THAT(model.output, HasSubstr("model.json"));
  EXPECT_THAT(model.output, HasSubstr("format is not"));
}

TEST(CliTest, ExploreBadInputIsNamed) {
  const auto dir = TempDir("explore_bad");
  const CliRun action = Toolbench("explore --actions throw --out " + dir.string());
  EXPECT_NE(action.code, 0);
  EXPECT_THAT(action.output, HasSubstr("throw"));
  const CliRun roll = Toolbench("explore --orientations 400 --out " + dir.string());
  EXPECT_NE(roll.code, 0);
  EXPECT_THAT(roll.output, HasSubstr("400"));
  const CliRun tools = Toolbench("explore --tools no_such_tool --out " + dir.string());
  EXPECT_NE(tools.code, 0);
  EXPECT_THAT(tools.output, HasSubstr("no_such_tool"));
}

}  // namespace
