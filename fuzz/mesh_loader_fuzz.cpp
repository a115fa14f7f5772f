// libFuzzer entry for the mesh readers and validators (toollib/mesh.h).
// The first input byte picks the format (.stl, .obj, .ply: byte % 3); the remaining bytes are
// written to a per-process temp file with that extension and read back with ReadMesh, then
// validated. Malformed input must end in std::invalid_argument; anything else (another
// exception, a crash, a sanitizer report, a hang) is a bug.
// Seed corpus: tests/data/meshes/**, each file prefixed with its selector byte
// (0 = stl, 1 = obj, 2 = ply).
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "toollib/mesh.h"

namespace {

std::filesystem::path TempPath(const char* extension) {
  return std::filesystem::temp_directory_path() /
         ("toolbench_mesh_fuzz_" + std::to_string(::getpid()) + extension);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  constexpr const char* kExtensions[] = {".stl", ".obj", ".ply"};
  const char* extension = kExtensions[size == 0 ? 0 : data[0] % 3];
  const std::filesystem::path path = TempPath(extension);
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (size > 1) {
      out.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
    }
  }
  try {
    const toolbench::toollib::TriangleMesh mesh = toolbench::toollib::ReadMesh(path);
    const toolbench::toollib::MeshReport report = toolbench::toollib::ValidateMesh(mesh);
    if (report.valid) {
      // A valid mesh encloses volume, so this must not throw. (HasSelfIntersections is left
      // out: it lives in the CGAL translation unit, which this target does not build.)
      (void)toolbench::toollib::Centroid(mesh);
    }
    toolbench::toollib::RequireValidMesh(mesh, path.string());
  } catch (const std::invalid_argument&) {
    // Expected for malformed input.
  }
  return 0;
}
