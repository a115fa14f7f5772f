#include "common/rng.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace toolbench {
namespace {

TEST(RngTest, SameSeedSameStream) {
  Rng a(DeriveSeed(7, "scene"));
  Rng b(DeriveSeed(7, "scene"));
  for (int i = 0; i < 100; ++i) EXPECT_EQ(UniformReal(a, -1, 1), UniformReal(b, -1, 1));
}

TEST(RngTest, StreamsAndSeedsDiffer) {
  EXPECT_NE(DeriveSeed(7, "scene"), DeriveSeed(7, "noise"));
  EXPECT_NE(DeriveSeed(7, "scene"), DeriveSeed(8, "scene"));
}

TEST(RngTest, UniformRealInRangeAndMeanNearCentre) {
  Rng rng(1);
  double sum = 0;
  for (int i = 0; i < 20000; ++i) {
    const double v = UniformReal(rng, 2.0, 4.0);
    ASSERT_GE(v, 2.0);
    ASSERT_LT(v, 4.0);
    sum += v;
  }
  EXPECT_NEAR(sum / 20000, 3.0, 0.02);
}

TEST(RngTest, StandardNormalMoments) {
  Rng rng(3);
  double sum = 0, sum2 = 0;
  constexpr int kN = 50000;
  for (int i = 0; i < kN; ++i) {
    const double v = StandardNormal(rng);
    sum += v;
    sum2 += v * v;
  }
  EXPECT_NEAR(sum / kN, 0.0, 0.02);
  EXPECT_NEAR(sum2 / kN, 1.0, 0.03);
}

TEST(RngTest, UniformIntCoversRange) {
  Rng rng(5);
  std::array<int, 4> hits{};
  for (int i = 0; i < 4000; ++i) ++hits[UniformInt(rng, 0, 3)];
  for (int h : hits) EXPECT_GT(h, 800);
}

}  // namespace
}  // namespace toolbench
