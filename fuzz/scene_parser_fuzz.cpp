// libFuzzer target: any bytes given to the scene parser either parse into a valid SceneSpec or
// raise std::invalid_argument. Anything else (crash, other exception, sanitizer report) is a bug.
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string_view>

#include "sim/scene_spec.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const toolbench::sim::SceneSpec spec = toolbench::sim::ParseSceneSpec(text, "fuzz");
    spec.Validate();  // a parsed spec is always valid
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
