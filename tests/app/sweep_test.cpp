#include "app/sweep.h"

#include <csignal>
#include <cstdlib>
#include <fstream>
#include <set>
#include <stdexcept>

#include <unistd.h>

#include <gtest/gtest.h>

namespace toolbench::app {
namespace {

std::filesystem::path TempDir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("toolbench_sweep_" + name);
  std::filesystem::remove_all(dir);
  return dir;
}

std::vector<SweepCase> Cases(int n) {
  std::vector<SweepCase> cases;
  for (int i = 0; i < n; ++i) cases.push_back({i, "case" + std::to_string(i), {{"x", i}}});
  return cases;
}

nlohmann::json Square(const SweepCase& c) { return {{"y", c.params["x"].get<int>() * c.params["x"].get<int>()}}; }

TEST(SweepTest, RunsEveryCaseInChildProcessesAndRecordsOneLineEach) {
  SweepOptions options;
  options.out_dir = TempDir("basic");
  options.protocol = "test";
  options.jobs = 2;
  const auto lines = RunSweep(options, Cases(5), Square);
  ASSERT_EQ(lines.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(lines[i]["index"], i);
    EXPECT_TRUE(lines[i]["ok"].get<bool>());
    EXPECT_EQ(lines[i]["result"]["y"], i * i);
  }
  EXPECT_TRUE(std::filesystem::exists(options.out_dir / "run.json"));
}

TEST(SweepTest, ThrowingCrashingAndHangingCasesAreRecordedAndTheSweepGoesOn) {
  SweepOptions options;
  options.out_dir = TempDir("failures");
  options.protocol = "test";
  options.jobs = 2;
  options.case_timeout_s = 1.0;
  auto run = [](const SweepCase& c) -> nlohmann::json {
    if (c.index == 1) throw std::invalid_argument("bad tool 'x'");
    if (c.index == 2) std::abort();
    if (c.index == 3) {
      for (;;) pause();
    }
    return {{"fine", true}};
  };
  const auto lines = RunSweep(options, Cases(5), run);
  ASSERT_EQ(lines.size(), 5u);
  EXPECT_TRUE(lines[0]["ok"].get<bool>());
  EXPECT_FALSE(lines[1]["ok"].get<bool>());
  EXPECT_NE(lines[1]["error"].get<std::string>().find("bad tool 'x'"), std::string::npos);
  EXPECT_NE(lines[2]["error"].get<std::string>().find("crashed: signal"), std::string::npos) << lines[2]["error"];
  EXPECT_NE(lines[3]["error"].get<std::string>().find("timeout"), std::string::npos) << lines[3]["error"];
  EXPECT_TRUE(lines[4]["ok"].get<bool>());
}

TEST(SweepTest, ShardsAreDisjointAndMergeToTheWholeSweep) {
  std::vector<std::filesystem::path> dirs;
  for (int shard = 0; shard < 3; ++shard) {
    SweepOptions options;
    options.out_dir = TempDir("shard" + std::to_string(shard));
    options.protocol = "test";
    options.shard_index = shard;
    options.shard_count = 3;
    options.isolate = shard != 1;  // in-process runs give the same lines
    for (const auto& line : RunSweep(options, Cases(7), Square)) EXPECT_EQ(line["index"].get<int>() % 3, shard);
    dirs.push_back(options.out_dir);
  }
  const auto merged = ReadSweepResults(dirs);
  ASSERT_EQ(merged.size(), 7u);
  for (int i = 0; i < 7; ++i) EXPECT_EQ(merged[i]["result"]["y"], i * i);
}

TEST(SweepTest, FilterSelectsCasesByIdAndABadRegexIsNamed) {
  SweepOptions options;
  options.out_dir = TempDir("filter");
  options.protocol = "test";
  options.filter = "case[13]$";
  const auto lines = RunSweep(options, Cases(5), Square);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0]["id"], "case1");
  EXPECT_EQ(lines[1]["id"], "case3");
  options.filter = "case[";
  EXPECT_THROW(RunSweep(options, Cases(5), Square), std::invalid_argument);
}

TEST(SweepTest, ResumeSkipsFinishedCases) {
  SweepOptions options;
  options.out_dir = TempDir("resume");
  options.protocol = "test";
  options.limit = 2;
  RunSweep(options, Cases(4), Square);
  options.limit = 0;
  options.resume = true;
  int calls = 0;
  options.isolate = false;  // count calls in this process
  const auto lines = RunSweep(options, Cases(4), [&](const SweepCase& c) {
    ++calls;
    return Square(c);
  });
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(lines.size(), 4u);
}

TEST(SweepTest, MalformedResultsAndBadOptionsAreNamed) {
  const auto dir = TempDir("malformed");
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "results.jsonl") << "{\"protocol\":\"test\",\"index\":0,\"id\":\"a\",\"ok\":true}\nnot json\n";
  try {
    ReadSweepResults({dir});
    FAIL() << "expected an exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("results.jsonl:2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ReadSweepResults({TempDir("missing")}), std::invalid_argument);
  SweepOptions options;
  options.out_dir = dir;
  options.jobs = 0;
  EXPECT_THROW(RunSweep(options, Cases(1), Square), std::invalid_argument);
}

}  // namespace
}  // namespace toolbench::app
