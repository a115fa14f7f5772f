#include "perception/internal/deterministic_heap.h"

#include <cstdint>
#include <cstdlib>
#include <memory>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "common/paths.h"
#include "perception/internal/parts_cgal.h"
#include "perception/model_fit.h"
#include "toollib/tool_model.h"

namespace toolbench::perception::internal {
namespace {

// Assertions run with the scope closed: a failure's message must not live in the heap.
TEST(DeterministicHeapTest, ServesTheScopeInAllocationOrderAndFreesWithTheHeap) {
  DeterministicHeap heap;
  std::vector<std::uintptr_t> addresses;
  addresses.reserve(100);
  {
    DeterministicHeap::Scope scope(heap);
    std::vector<std::unique_ptr<int>> kept;
    for (int i = 0; i < 100; ++i) {
      kept.push_back(std::make_unique<int>(i));
      addresses.push_back(reinterpret_cast<std::uintptr_t>(kept.back().get()));
      if (i % 3 == 0) kept.erase(kept.begin());  // frees do not hand memory back
    }
    scope.Close();
    for (std::size_t i = 1; i < addresses.size(); ++i) EXPECT_LT(addresses[i - 1], addresses[i]);
    for (const auto& p : kept) EXPECT_TRUE(heap.Owns(p.get()));
    const auto after_close = std::make_unique<int>(1);  // the normal heap again
    EXPECT_FALSE(heap.Owns(after_close.get()));
    // `kept` (heap memory) is deleted here, after the scope closed: a no-op.
  }
  EXPECT_GE(heap.used_bytes(), 100 * sizeof(int));
  EXPECT_FALSE(heap.overflowed());
  const auto outside = std::make_unique<double>(2.0);
  EXPECT_FALSE(heap.Owns(outside.get()));
}

TEST(DeterministicHeapTest, AlignsOverAlignedTypes) {
  struct alignas(64) Line {
    char bytes[64];
  };
  DeterministicHeap heap;
  DeterministicHeap::Scope scope(heap);
  const auto small = std::make_unique<char>('x');
  const auto line = std::make_unique<Line>();
  scope.Close();
  EXPECT_TRUE(heap.Owns(small.get()));
  EXPECT_TRUE(heap.Owns(line.get()));
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(line.get()) % 64, 0u);
}

TEST(DeterministicHeapTest, FallsBackToMallocWhenFullAndRefusesMisuse) {
  DeterministicHeap heap(4096);
  {
    DeterministicHeap::Scope scope(heap);
    const auto big = std::make_unique<std::vector<char>>(8192, 'a');  // larger than the heap
    bool nested_refused = false;
    try {
      DeterministicHeap::Scope nested(heap);
    } catch (const std::logic_error&) {
      nested_refused = true;
    }
    scope.Close();
    EXPECT_TRUE(nested_refused);
    EXPECT_TRUE(heap.Owns(big.get()));
    EXPECT_FALSE(heap.Owns(big->data()));
    EXPECT_EQ((*big)[8191], 'a');
    EXPECT_TRUE(heap.overflowed());
  }
  EXPECT_THROW(DeterministicHeap second, std::logic_error);
  EXPECT_THROW(DeterministicHeap zero(0), std::invalid_argument);
}

// The reason for the heap: CGAL's advancing-front reconstruction takes equally good border edges
// in address order, so the surface of one cloud depended on what the process had allocated
// before (rake_4's, with this test's allocations in between and no heap: 7972 facets, then 7977).
TEST(AdvancingFrontFacetsTest, SameSurfaceWhateverWasAllocatedBefore) {
  const toollib::ToolModel model = toollib::LoadToolModel(AssetsDir() / "tools" / "rake_4.json");
  const SurfaceSamples samples = SampleSurface(model.mesh, 4000, 1);
  std::mt19937 rng(1);
  std::vector<void*> junk;
  std::vector<std::vector<Eigen::Vector3i>> surfaces;
  for (int run = 0; run < 3; ++run) {
    for (int k = 0; k < 2000; ++k) {
      junk.push_back(std::malloc(8 + rng() % 300));
      if (rng() % 3 == 0) {
        const std::size_t i = rng() % junk.size();
        std::free(junk[i]);
        junk[i] = nullptr;
      }
    }
    surfaces.push_back(AdvancingFrontFacets(samples.points, samples.normals));
  }
  for (void* p : junk) std::free(p);
  ASSERT_GT(surfaces[0].size(), 1000u);
  for (int run = 1; run < 3; ++run) {
    ASSERT_EQ(surfaces[run].size(), surfaces[0].size()) << "run " << run;
    for (std::size_t f = 0; f < surfaces[0].size(); ++f) {
      ASSERT_EQ(surfaces[run][f], surfaces[0][f]) << "run " << run << ", facet " << f;
    }
  }
}

}  // namespace
}  // namespace toolbench::perception::internal
