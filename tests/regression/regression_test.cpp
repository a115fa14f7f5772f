// Regression suite: fixed, seeded benchmark subsets whose metrics must stay within the bounds of
// tests/regression/thresholds.json. A failure prints every metric against its bound.
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace {

struct Suite {
  std::string name;
  nlohmann::json spec;
};

std::vector<Suite> LoadSuites() {
  std::ifstream in(TOOLBENCH_REGRESSION_THRESHOLDS);
  const nlohmann::json all = nlohmann::json::parse(in);
  std::vector<Suite> suites;
  for (const auto& s : all.at("suites")) suites.push_back({s.at("name").get<std::string>(), s});
  return suites;
}

// gtest prints parameters in test listings; without this it dumps the struct's bytes.
void PrintTo(const Suite& suite, std::ostream* os) { *os << suite.name; }

class RegressionTest : public ::testing::TestWithParam<Suite> {};

TEST_P(RegressionTest, MetricsWithinThresholds) {
  const Suite& suite = GetParam();
  const auto out = std::filesystem::temp_directory_path() / ("toolbench_regression_" + suite.name);
  std::filesystem::remove_all(out);
  // Each argument single-quoted for the shell (regex filters hold | ( ) ^ $).
  std::string cmd = std::string(TOOLBENCH_EXE);
  for (const auto& arg : suite.spec.at("args")) cmd += " '" + arg.get<std::string>() + "'";
  cmd += " --out '" + out.string() + "' 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  std::array<char, 4096> buffer{};
  while (size_t n = fread(buffer.data(), 1, buffer.size(), pipe)) output.append(buffer.data(), n);
  const int status = pclose(pipe);
  ASSERT_EQ(status, 0) << output;
  std::ifstream in(out / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(in);
  std::string table = "\n  metric                        value      bound      ok\n";
  bool all_ok = true;
  for (const auto& check : suite.spec.at("checks")) {
    const std::string metric = check.at("metric");
    const nlohmann::json::json_pointer pointer(metric);
    ASSERT_TRUE(summary.contains(pointer)) << suite.name << ": summary.json has no " << metric;
    const double value = summary.at(pointer).get<double>();
    bool ok = true;
    std::string bound;
    if (check.contains("min")) {
      ok = ok && value >= check["min"].get<double>();
      bound += ">= " + std::to_string(check["min"].get<double>());
    }
    if (check.contains("max")) {
      ok = ok && value <= check["max"].get<double>();
      bound += (bound.empty() ? "" : ", ") + std::string("<= ") + std::to_string(check["max"].get<double>());
    }
    all_ok = all_ok && ok;
    char line[256];
    std::snprintf(line, sizeof line, "  %-28s %-10.4f %-10s %s\n", metric.c_str(), value, bound.c_str(),
                  ok ? "ok" : "REGRESSED");
    table += line;
  }
  std::printf("[regression] %s (results in %s)%s", suite.name.c_str(), out.string().c_str(), table.c_str());
  EXPECT_TRUE(all_ok) << suite.name << ": metrics out of bounds" << table;
}

INSTANTIATE_TEST_SUITE_P(Suites, RegressionTest, ::testing::ValuesIn(LoadSuites()),
                         [](const ::testing::TestParamInfo<Suite>& info) { return info.param.name; });

}  // namespace
