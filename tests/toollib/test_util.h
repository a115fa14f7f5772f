#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

#include <gtest/gtest.h>

namespace toolbench::toollib::testing {

/// tests/data/meshes/<name> (TOOLBENCH_TEST_DATA_DIR is set by tests/toollib/CMakeLists.txt).
inline std::filesystem::path MeshData(const std::string& name) {
  return std::filesystem::path(TOOLBENCH_TEST_DATA_DIR) / "meshes" / name;
}

/// A fresh, empty folder for the current test, unique per process and test name.
inline std::filesystem::path FreshTempDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("toollib_" + std::string(info->test_suite_name()) + "_" +
                                     info->name() + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace toolbench::toollib::testing
