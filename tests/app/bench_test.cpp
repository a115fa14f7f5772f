#include "app/bench.h"

#include <fstream>
#include <stdexcept>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "app/bench_episodes.h"
#include "app/bench_grasp.h"
#include "app/bench_ik.h"
#include "app/bench_pull.h"
#include "app/plots.h"

// PLplot's cairo driver leaves fontconfig's caches and libltdl's driver handles allocated at exit
// (library-global state, not ours); LeakSanitizer (the sanitizer build) is told to ignore those two
// libraries only. Without a sanitizer this hook is never called.
extern "C" const char* __lsan_default_suppressions() { return "leak:libfontconfig.so\nleak:libltdl.so\n"; }

namespace toolbench::app {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

std::filesystem::path TempDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("toolbench_bench_" + name);
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

nlohmann::json ReadJson(const std::filesystem::path& file) {
  std::ifstream in(file);
  return nlohmann::json::parse(in);
}

std::string ReadText(const std::filesystem::path& file) {
  std::ifstream in(file);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(BenchTest, ToolCellCasesNumberToolsMajor) {
  const auto cases = ToolCellCases({"a", "b"}, {"pos1", "rot2", "pos3_rot1"});
  ASSERT_EQ(cases.size(), 6u);
  EXPECT_EQ(cases[4].index, 4);
  EXPECT_EQ(cases[4].id, "b/rot2");
  EXPECT_EQ(cases[4].params["tool"], "b");
  EXPECT_EQ(cases[5].params["cell"], "pos3_rot1");
}

TEST(BenchTest, WilsonIntervalMatchesTheFormula) {
  // 8 of 10: p = 0.8, z = 1.96 -> [0.490, 0.943] (Wilson 1927, standard tables).
  const auto [lo, hi] = WilsonInterval(8, 10);
  EXPECT_NEAR(lo, 0.4902, 1e-3);
  EXPECT_NEAR(hi, 0.9433, 1e-3);
  EXPECT_EQ(WilsonInterval(0, 0), std::make_pair(0.0, 1.0));
  const auto [lo0, hi0] = WilsonInterval(0, 20);
  EXPECT_EQ(lo0, 0.0);
  EXPECT_GT(hi0, 0.1);
  Tally t;
  t.Add(true);
  t.Add(false);
  EXPECT_DOUBLE_EQ(t.Rate(), 0.5);
  EXPECT_TRUE(std::isnan(Tally{}.Rate()));
  const BarSeries s = RateSeries("x", {t, Tally{}});
  EXPECT_DOUBLE_EQ(s.values[0], 50.0);
  EXPECT_LT(s.low[0], 50.0);
  EXPECT_GT(s.high[0], 50.0);
  EXPECT_TRUE(std::isnan(s.values[1]) && std::isnan(s.low[1]));
}

TEST(PlotsTest, BarChartAndHistogramsArePngsOfTheRequestedSize) {
  const auto dir = TempDir("plots");
  BarChart chart;
  chart.title = "rates";
  chart.x_label = "cell";
  chart.y_label = "success [%]";
  chart.categories = {"pos1", "pos2", "rot#1"};
  chart.series = {{"ours", {10, 50, 90}, {5, 40, 80}, {20, 60, 95}}, {"thesis", {20, std::nan(""), 70}, {}, {}}};
  chart.value_labels = true;
  chart.width_px = 640;
  chart.height_px = 400;
  WriteBarChartPng(chart, dir / "bars.png");
  const cv::Mat bars = cv::imread((dir / "bars.png").string());
  ASSERT_FALSE(bars.empty());
  EXPECT_EQ(bars.cols, 640);
  EXPECT_EQ(bars.rows, 400);
  // Something was drawn: not a blank page.
  cv::Scalar mean = cv::mean(bars);
  EXPECT_LT(mean[0], 250.0);

  Histogram h;
  h.title = "stage";
  h.x_label = "wall time [s]";
  h.values = {1, 2, 2, 3, 3, 3, std::nan("")};
  Histogram empty;
  empty.title = "never ran";
  WriteHistogramsPng({h, h, empty}, dir / "hist.png", 2, 300, 250);
  const cv::Mat hist = cv::imread((dir / "hist.png").string());
  ASSERT_FALSE(hist.empty());
  EXPECT_EQ(hist.cols, 600);
  EXPECT_EQ(hist.rows, 500);
}

TEST(PlotsTest, BadChartsAreNamed) {
  const auto dir = TempDir("plots_bad");
  BarChart chart;
  chart.title = "broken";
  EXPECT_THAT([&] { WriteBarChartPng(chart, dir / "a.png"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no categories")));
  chart.categories = {"a", "b"};
  chart.series = {{"s", {1.0}, {}, {}}};
  EXPECT_THAT([&] { WriteBarChartPng(chart, dir / "a.png"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("1 values for 2 categories")));
  chart.series = {{"s", {1.0, 2.0}, {0.5}, {1.5}}};
  EXPECT_THAT([&] { WriteBarChartPng(chart, dir / "a.png"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("interval")));
  chart.series = {{"s", {1.0, 2.0}, {}, {}}};
  chart.width_px = 50;
  EXPECT_THAT([&] { WriteBarChartPng(chart, dir / "a.png"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("image size")));
  Histogram h;
  h.bins = 0;
  EXPECT_THAT([&] { WriteHistogramsPng({h}, dir / "h.png"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("bins = 0")));
  EXPECT_THAT([&] { WriteHistogramsPng({}, dir / "h.png"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no panels")));
}

SweepLine GraspLine(int index, const std::string& tool, const std::string& cell, bool success,
                    const std::string& reason, double handle_centre_slip_m = 0.001) {
  return {{"protocol", "grasp-gt"},
          {"index", index},
          {"id", tool + "/" + cell},
          {"ok", true},
          {"result",
           {{"tool", tool},
            {"cell", cell},
            {"success", success},
            {"reason", reason},
            {"wall_ms", 100.0},
            {"sim_time_s", 5.0},
            {"slip_m", 0.001},
            {"handle_centre_slip_m", handle_centre_slip_m},
            {"slip_deg", 2.0}}}};
}

TEST(BenchReportTest, GraspReportCountsPerCellAndToolAndDrawsThem) {
  BenchRequest request;
  request.out_dir = TempDir("grasp_report");
  std::vector<SweepLine> lines = {GraspLine(0, "hoe_1", "pos1", true, ""),
                                  GraspLine(1, "hoe_1", "rot2", false, "slip: 6 mm", /*handle_centre_slip_m=*/0.004),
                                  GraspLine(2, "rake_1", "pos1", true, ""),
                                  GraspLine(3, "rake_1", "rot2", true, "", /*handle_centre_slip_m=*/0.006),
                                  GraspLine(5, "rake_2", "rot2", false, "unreachable: no palm pose")};
  lines.push_back({{"protocol", "grasp-gt"}, {"index", 4}, {"id", "x/pos1"}, {"ok", false}, {"error", "crashed"}});
  ReportGrasp(request, lines);
  const nlohmann::json summary = ReadJson(request.out_dir / "summary.json");
  EXPECT_EQ(summary["cases"], 5);
  EXPECT_EQ(summary["failed_cases"], 1);
  EXPECT_DOUBLE_EQ(summary["grasp_success_rate"].get<double>(), 0.6);
  EXPECT_EQ(summary["cells_grasped"], 3);
  EXPECT_EQ(summary["start"], "home");  // lines without "start" came from the home posture
  EXPECT_EQ(summary["cells_out_of_reach"], 1);
  EXPECT_DOUBLE_EQ(summary["grasp_success_rate_within_reach"].get<double>(), 0.75);
  EXPECT_DOUBLE_EQ(summary["per_cell"]["rot2"].get<double>(), 1.0 / 3.0);
  EXPECT_DOUBLE_EQ(summary["per_tool"]["rake_1"].get<double>(), 1.0);
  EXPECT_EQ(summary["failure_reasons"]["slip"], 1);
  // rake_1/rot2 held where the hand holds it, but its handle centre moved 6 mm; hoe_1/rot2 the
  // other way round: by the criterion before session 48, counted beside, one lost and one gained.
  EXPECT_EQ(summary["cells_grasped_by_handle_centre"], 3);
  EXPECT_DOUBLE_EQ(summary["slip_deg_median_successful"].get<double>(), 2.0);
  const std::string md = ReadText(request.out_dir / "summary.md");
  EXPECT_THAT(md, HasSubstr("![grasp success per cell](per_cell.png)"));
  EXPECT_THAT(md, HasSubstr("Grasped 3 of 5 cells (60 %). 1 cells have no palm pose"));
  EXPECT_THAT(md, HasSubstr("of the other 4, 75 % were grasped"));
  EXPECT_THAT(md, HasSubstr("moved 1.0 mm in the hand and turned 2.0 deg"));
  EXPECT_THAT(md, HasSubstr("Judged by the handle's centre instead of the point held (sessions before 48), 3 cells"));
  EXPECT_THAT(md, HasSubstr("started from the home posture"));
  EXPECT_TRUE(std::filesystem::exists(request.out_dir / "per_cell.png"));
  EXPECT_TRUE(std::filesystem::exists(request.out_dir / "per_tool.png"));
}

TEST(BenchReportTest, IkReportSeparatesReachableAndUnreachableTargets) {
  BenchRequest request;
  request.out_dir = TempDir("ik_report");
  auto config = [](bool success, double ms) {
    return nlohmann::json{{"status", success ? "converged" : "max_iterations"},
                          {"success", success},
                          {"position_error_m", success ? 1e-4 : 0.1},
                          {"orientation_error_deg", 0.1},
                          {"iterations", 5},
                          {"rest_cost", 0.2},
                          {"solve_ms", ms}};
  };
  auto line = [&](int index, bool reachable, bool success) {
    nlohmann::json configs;
    for (const char* name : {"default", "baseline_plain_ipopt", "presolve_then_ipopt_polish"}) {
      configs[name] = config(success, 2.0);
    }
    return SweepLine{{"protocol", "ik"},
                     {"index", index},
                     {"id", std::to_string(index)},
                     {"ok", true},
                     {"result", {{"reachable", reachable}, {"configs", configs}}}};
  };
  ReportIk(request, {line(0, true, true), line(1, true, false), line(2, false, true)});
  const nlohmann::json summary = ReadJson(request.out_dir / "summary.json");
  EXPECT_EQ(summary["reachable_cases"], 2);
  EXPECT_DOUBLE_EQ(summary["success_rate"].get<double>(), 0.5);
  EXPECT_EQ(summary["unreachable_cases"], 1);
  EXPECT_DOUBLE_EQ(summary["unreachable_reported_rate"].get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(summary["baseline"]["success_rate"].get<double>(), 0.5);
}

TEST(HindsightTest, RightWhenTheChosenToolBringsTheBallIntoReach) {
  auto pull = [](const char* tool, bool in_reach, double m) {
    return nlohmann::json{{"tool", tool}, {"ball_in_reach", in_reach}, {"displacement_m", m}};
  };
  // In reach beats a longer pull that stops short of it (or flings the ball past the robot).
  const nlohmann::json pulls = {pull("hoe_1", false, 0.60), pull("rake_3", true, 0.12), pull("stick_2", false, 0.0)};
  nlohmann::json j = JudgeChoiceInHindsight(pulls, "rake_3");
  EXPECT_EQ(j["best_tool"], "rake_3");
  EXPECT_EQ(j["in_reach"], 1);
  EXPECT_TRUE(j["correct"].get<bool>());
  EXPECT_NEAR(j["chance"].get<double>(), 1.0 / 3, 1e-12);
  EXPECT_FALSE(JudgeChoiceInHindsight(pulls, "hoe_1")["correct"].get<bool>());
  // Two tools in reach: either does the job; the longer pull is the best.
  const nlohmann::json two = {pull("hoe_1", true, 0.15), pull("rake_3", true, 0.25), pull("stick_2", false, 0.3)};
  EXPECT_EQ(JudgeChoiceInHindsight(two, "hoe_1")["best_tool"], "rake_3");
  EXPECT_TRUE(JudgeChoiceInHindsight(two, "hoe_1")["correct"].get<bool>());
  EXPECT_NEAR(JudgeChoiceInHindsight(two, "hoe_1")["chance"].get<double>(), 2.0 / 3, 1e-12);
  // No tool brought it into reach: nothing to agree with.
  const nlohmann::json none = {pull("hoe_1", false, 0.07), pull("rake_3", false, 0.02)};
  EXPECT_EQ(JudgeChoiceInHindsight(none, "rake_3")["best_tool"], "hoe_1");
  EXPECT_FALSE(JudgeChoiceInHindsight(none, "hoe_1").contains("correct"));
  EXPECT_THAT([] { JudgeChoiceInHindsight(nlohmann::json::array(), "hoe_1"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("no pulls")));
  EXPECT_THAT([] { JudgeChoiceInHindsight(nlohmann::json::array({{{"tool", "x"}}}), "x"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("lacks")));
}

TEST(BenchReportTest, RandomReportScoresTheChoiceBesideChance) {
  BenchRequest request;
  request.out_dir = TempDir("random_report");
  auto line = [](int index, bool correct, double chance) {
    nlohmann::json truth = {{"choice_correct", correct}, {"hindsight", {{"chance", chance}}}};
    nlohmann::json stages = nlohmann::json::array(
        {{{"name", "choose_tool"}, {"ok", true}, {"wall_ms", 1.0}, {"robot_s", 0.0}}});
    return SweepLine{{"protocol", "random"},
                     {"index", index},
                     {"id", "episode/" + std::to_string(index)},
                     {"ok", true},
                     {"result",
                      {{"ball_reachable_at_start", false},
                       {"grasp_success", true},
                       {"pull_success", correct},
                       {"ball_grasp_success", false},
                       {"assisted", false},
                       {"achieved_displacement_m", 0.1},
                       {"failure", ""},
                       {"wall_s", 10.0},
                       {"stages", stages},
                       {"truth", truth}}}};
  };
  ReportRandomEpisodes(request, {line(0, true, 0.5), line(1, false, 1.0 / 3), line(2, true, 1.0)});
  const nlohmann::json summary = ReadJson(request.out_dir / "summary.json");
  EXPECT_EQ(summary["choice_correct"]["successes"], 2);
  EXPECT_EQ(summary["choice_correct"]["n"], 3);
  EXPECT_NEAR(summary["choice_correct_by_chance"].get<double>(), (0.5 + 1.0 / 3 + 1.0) / 3, 1e-12);
  EXPECT_THAT(ReadText(request.out_dir / "summary.md"), HasSubstr("a random pick would be right 61 %"));
}

// The own-grasp rate also over the episodes whose tool's handle was within reach (a grasp
// planned), as grasp-gt rates the cells, over the episodes that looked at the rack again after a
// failed grasp, and the perception of the tool gone for.
TEST(BenchReportTest, RandomReportRatesGraspsWithinReachAndThePerceptionOfTheChosenTool) {
  BenchRequest request;
  request.out_dir = TempDir("random_report_reach");
  auto line = [](int index, bool planned, bool grasped, double score, int looks_again = 0) {
    nlohmann::json stages =
        nlohmann::json::array({{{"name", "grasp_tool"},
                                {"ok", true},
                                {"wall_ms", 1.0},
                                {"details", {{"grasp_planned", planned}, {"looks_again", looks_again}}}}});
    nlohmann::json truth;
    truth["chosen_tool_perception"]["score"] = score;
    const nlohmann::json result = {
        {"ball_reachable_at_start", false}, {"grasp_success", grasped}, {"stages", stages}, {"truth", truth}};
    return SweepLine{{"protocol", "random"},
                     {"index", index},
                     {"id", "episode/" + std::to_string(index)},
                     {"ok", true},
                     {"result", result}};
  };
  ReportRandomEpisodes(request, {line(0, true, true, 1.0), line(1, false, false, 1.0), line(2, true, false, 0.5, 1),
                                 line(3, true, true, 0.0, 1)});
  const nlohmann::json summary = ReadJson(request.out_dir / "summary.json");
  EXPECT_EQ(summary["grasp_success"]["successes"], 2);
  EXPECT_EQ(summary["grasp_success"]["n"], 4);
  EXPECT_EQ(summary["grasp_success_within_reach"]["successes"], 2);
  EXPECT_EQ(summary["grasp_success_within_reach"]["n"], 3);
  EXPECT_EQ(summary["grasp_success_after_look_again"]["successes"], 1);
  EXPECT_EQ(summary["grasp_success_after_look_again"]["n"], 2);
  EXPECT_EQ(summary["chosen_tool_perceived"]["successes"], 2);
  EXPECT_EQ(summary["chosen_tool_perceived"]["n"], 4);
}

// Why the robot was helped, from the stages an assisted episode ran.
TEST(BenchReportTest, HelpReasonNamesTheHandOverOrTheReGrip) {
  auto result = [](nlohmann::json stages) { return nlohmann::json{{"assisted", true}, {"stages", stages}}; };
  auto grasp = [](const char* outcome, bool planned) {
    return nlohmann::json{{"name", "grasp_tool"}, {"outcome", outcome}, {"details", {{"grasp_planned", planned}}}};
  };
  EXPECT_EQ(HelpReason(result({grasp("handed_over", false)})), "hand-over: the handle out of reach");
  EXPECT_EQ(HelpReason(result({grasp("handed_over", true)})), "hand-over: the grasp failed");
  EXPECT_EQ(HelpReason(result({grasp("grasped", true), {{"name", "inspect_tool"}}, {{"name", "re_grip"}}})),
            "re-grip: the look at the tool in the hand found none");
  EXPECT_EQ(HelpReason(result({grasp("grasped", true),
                               {{"name", "pull"}, {"details", {{"regrip_after", "unreachable: ..."}}}}})),
            "re-grip: no plan of the action from the robot's own grip");
  EXPECT_EQ(HelpReason(result({grasp("grasped", true)})), "other");

  BenchRequest request;
  request.out_dir = TempDir("random_report_help");
  auto line = [&](int index, const nlohmann::json& r) {
    nlohmann::json full = r;
    full["ball_reachable_at_start"] = false;
    for (auto& s : full["stages"]) s["wall_ms"] = 1.0;
    return SweepLine{{"protocol", "random"}, {"index", index}, {"ok", true}, {"result", full}};
  };
  ReportRandomEpisodes(request, {line(0, result({grasp("handed_over", false)})),
                                 line(1, result({grasp("handed_over", false)})),
                                 line(2, result({grasp("handed_over", true)})),
                                 line(3, {{"assisted", false}, {"stages", {grasp("grasped", true)}}})});
  const nlohmann::json summary = ReadJson(request.out_dir / "summary.json");
  EXPECT_EQ(summary["help_reasons"]["hand-over: the handle out of reach"], 2);
  EXPECT_EQ(summary["help_reasons"]["hand-over: the grasp failed"], 1);
  EXPECT_EQ(summary["help_reasons"].size(), 2u);
  EXPECT_THAT(ReadText(request.out_dir / "summary.md"), HasSubstr("| hand-over: the handle out of reach | 2 |"));
}

TEST(BenchTest, OptionsOfOtherProtocolsAreRejected) {
  BenchRequest request;
  request.protocol = "grasp-gt";
  request.out_dir = TempDir("extended");
  request.extended = true;
  EXPECT_THAT([&] { RunBench(request); }, ThrowsMessage<std::invalid_argument>(HasSubstr("--extended")));
  request.extended = false;
  request.hindsight = true;
  EXPECT_THAT([&] { RunBench(request); }, ThrowsMessage<std::invalid_argument>(HasSubstr("--hindsight")));
  request.hindsight = false;
  request.check_action_before_grasp = false;
  EXPECT_THAT([&] { RunBench(request); }, ThrowsMessage<std::invalid_argument>(HasSubstr("--no-action-check")));
  request.check_action_before_grasp = true;
  request.look_again_after_failed_grasp = false;
  EXPECT_THAT([&] { RunBench(request); }, ThrowsMessage<std::invalid_argument>(HasSubstr("--no-look-again")));
  request.look_again_after_failed_grasp = true;
  request.protocol = "random";
  request.from_rack_look = true;
  EXPECT_THAT([&] { RunBench(request); }, ThrowsMessage<std::invalid_argument>(HasSubstr("--from-rack-look")));
}

}  // namespace
}  // namespace toolbench::app
