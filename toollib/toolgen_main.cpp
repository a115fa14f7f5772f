// toolbench_toolgen: regenerates the tool library (assets/tools).
// Usage: toolbench_toolgen <output dir>
// Writes <name>.stl + <name>.json per tool and prints a markdown table of the variants
// (the one in assets/tools/README.md) on stdout.
#include <cstdio>
#include <exception>
#include <filesystem>
#include <string>
#include <vector>

#include "toollib/generator.h"
#include "toollib/mesh.h"
#include "toollib/tool_model.h"

namespace {

void PrintTable(const std::vector<toolbench::toollib::ToolModel>& tools) {
  std::printf(
      "| name | family | total length [m] | handle diameter [mm] | faces | volume [cm^3] | "
      "mass [kg] | collision parts |\n");
  std::printf("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |\n");
  for (const auto& tool : tools) {
    std::printf("| %s | %s | %.3f | %.0f | %d | %.1f | %.3f | %d |\n", tool.name.c_str(),
                tool.family.c_str(), tool.total_length, 2000.0 * tool.handle.radius,
                static_cast<int>(tool.mesh.faces.cols()),
                1e6 * toolbench::toollib::Volume(tool.mesh), tool.mass,
                static_cast<int>(tool.collision.size()));
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2 || std::string(argv[1]) == "--help") {
    std::fprintf(stderr, "usage: %s <output dir>\n", argv[0]);
    return argc == 2 ? 0 : 2;
  }
  try {
    const std::filesystem::path dir = argv[1];
    const auto tools = toolbench::toollib::GenerateToolLibrary();
    for (const auto& tool : tools) {
      toolbench::toollib::SaveToolModel(tool, dir);
    }
    PrintTable(tools);
    std::fprintf(stderr, "wrote %zu tools to %s\n", tools.size(), dir.string().c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "toolbench_toolgen: %s\n", e.what());
    return 1;
  }
  return 0;
}
