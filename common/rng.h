#pragma once

#include <cstdint>
#include <random>
#include <string_view>

namespace toolbench {

/// The one random engine type of the project. Every draw comes from an engine seeded explicitly.
using Rng = std::mt19937_64;

/// Derives an independent, reproducible seed for a named stream ("scene", "noise", ...) from a
/// master seed, so that adding draws to one stream does not shift another (SplitMix64 mixing).
std::uint64_t DeriveSeed(std::uint64_t master_seed, std::string_view stream);

/// Uniform double in [lo, hi) drawn from rng; portable across standard libraries, unlike
/// std::uniform_real_distribution, so a seed gives the same scene everywhere.
double UniformReal(Rng& rng, double lo, double hi);

/// Standard normal draw (Box-Muller on UniformReal), portable across standard libraries.
double StandardNormal(Rng& rng);

/// Uniform integer in [lo, hi], portable across standard libraries.
int UniformInt(Rng& rng, int lo, int hi);

}  // namespace toolbench
