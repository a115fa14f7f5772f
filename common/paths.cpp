#include "common/paths.h"

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

#include "common/check.h"

namespace toolbench {

std::filesystem::path SourceRoot() {
  if (const char* env = std::getenv("TOOLBENCH_ROOT"); env != nullptr && env[0] != '\0') {
    return std::filesystem::path(env);
  }
  return std::filesystem::path(TOOLBENCH_SOURCE_ROOT);
}

std::filesystem::path AssetsDir() { return SourceRoot() / "assets"; }

std::filesystem::path ScenesDir() { return SourceRoot() / "scenes"; }

std::string ReadTextFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) ThrowInvalid("cannot read file '", path.string(), "'");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

void WriteTextFile(const std::filesystem::path& path, const std::string& text) {
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out) throw std::runtime_error(Cat("cannot write file '", path.string(), "'"));
}

}  // namespace toolbench
