#include "common/check.h"

#include <cstdio>
#include <cstdlib>

namespace toolbench {

void DemandFailed(const char* condition, const char* file, int line) {
  std::fprintf(stderr, "toolbench: internal invariant failed: %s at %s:%d\n", condition, file, line);
  std::abort();
}

}  // namespace toolbench
