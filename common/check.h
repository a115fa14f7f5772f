#pragma once

#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace toolbench {

/// Aborts with file:line and the failed condition. Used for broken internal invariants only;
/// bad input to a public function throws std::invalid_argument instead (style.md, section 6).
[[noreturn]] void DemandFailed(const char* condition, const char* file, int line);

/// Builds a message from any streamable parts: Cat("bad value ", 3, " for 'x'").
template <typename... Parts>
std::string Cat(Parts&&... parts) {
  std::ostringstream out;
  (out << ... << std::forward<Parts>(parts));
  return out.str();
}

/// Throws std::invalid_argument with the concatenated message.
template <typename... Parts>
[[noreturn]] void ThrowInvalid(Parts&&... parts) {
  throw std::invalid_argument(Cat(std::forward<Parts>(parts)...));
}

}  // namespace toolbench

/// Always-on invariant check (never compiled out, unlike assert).
#define TOOLBENCH_DEMAND(condition)                                   \
  do {                                                                \
    if (!(condition)) {                                               \
      ::toolbench::DemandFailed(#condition, __FILE__, __LINE__);      \
    }                                                                 \
  } while (false)
