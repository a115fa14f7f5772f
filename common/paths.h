#pragma once

#include <filesystem>

namespace toolbench {

/// Root of the toolbench source tree (holds assets/ and scenes/). Taken from the environment
/// variable TOOLBENCH_ROOT when set, else the path CMake configured; never the working directory.
std::filesystem::path SourceRoot();

/// SourceRoot() / "assets".
std::filesystem::path AssetsDir();

/// SourceRoot() / "scenes".
std::filesystem::path ScenesDir();

/// Reads a whole file. Throws std::invalid_argument naming the path when it cannot be read.
std::string ReadTextFile(const std::filesystem::path& path);

/// Writes a whole file, creating parent folders. Throws std::runtime_error naming the path on failure.
void WriteTextFile(const std::filesystem::path& path, const std::string& text);

}  // namespace toolbench
