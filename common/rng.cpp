#include "common/rng.h"

#include <cmath>
#include <numbers>

#include "common/check.h"

namespace toolbench {

std::uint64_t DeriveSeed(std::uint64_t master_seed, std::string_view stream) {
  // FNV-1a of the stream name, then SplitMix64 of the combination.
  std::uint64_t h = 1469598103934665603ull;
  for (char c : stream) {
    h ^= static_cast<unsigned char>(c);
    h *= 1099511628211ull;
  }
  std::uint64_t z = master_seed + 0x9e3779b97f4a7c15ull * (h | 1ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

double UniformReal(Rng& rng, double lo, double hi) {
  // 53 random bits -> [0, 1).
  const double unit = static_cast<double>(rng() >> 11) * 0x1.0p-53;
  return lo + (hi - lo) * unit;
}

double StandardNormal(Rng& rng) {
  double u1 = UniformReal(rng, 0.0, 1.0);
  if (u1 < 1e-300) u1 = 1e-300;
  const double u2 = UniformReal(rng, 0.0, 1.0);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

int UniformInt(Rng& rng, int lo, int hi) {
  TOOLBENCH_DEMAND(lo <= hi);
  const std::uint64_t span = static_cast<std::uint64_t>(static_cast<std::int64_t>(hi) - lo) + 1;
  return lo + static_cast<int>(rng() % span);
}

}  // namespace toolbench
