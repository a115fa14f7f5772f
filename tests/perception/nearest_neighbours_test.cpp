#include "perception/internal/nearest_neighbours.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "common/rng.h"

namespace toolbench::perception::internal {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

Eigen::Matrix3Xf RandomPoints(int count, std::uint64_t seed) {
  Rng rng(seed);
  Eigen::Matrix3Xf p(3, count);
  for (int i = 0; i < count; ++i) {
    for (int a = 0; a < 3; ++a) p(a, i) = static_cast<float>(UniformReal(rng, -0.2, 0.2));
  }
  return p;
}

// The squared distance exactly as FLANN's L2_Simple sums it (float, x then y then z).
float SquaredDistance(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  float sum = 0.0f;
  for (int k = 0; k < 3; ++k) sum += (a[k] - b[k]) * (a[k] - b[k]);
  return sum;
}

TEST(NearestNeighboursTest, AnswersEqualAnExhaustiveSearch) {
  Eigen::Matrix3Xf points = RandomPoints(3000, 1);
  // Exact duplicates: a tie must still name a point at the nearest distance.
  points.col(10) = points.col(20);
  points.col(2999) = points.col(20);
  const NearestNeighbours nn(points);
  EXPECT_EQ(nn.size(), 3000);

  Eigen::Matrix3Xf queries(3, 1003);
  queries.leftCols(1000) = RandomPoints(1000, 2) * 1.5f;  // some outside the points' box
  queries.col(1000) = points.col(20);                      // on the duplicated point
  queries.col(1001) = points.col(7);                       // on a data point
  queries.col(1002) = Eigen::Vector3f(5.0f, -3.0f, 2.0f);  // far away
  std::vector<int> index;
  std::vector<float> sq_distance;
  nn.Find(queries, index, sq_distance);
  ASSERT_EQ(index.size(), 1003u);
  ASSERT_EQ(sq_distance.size(), 1003u);
  for (Eigen::Index q = 0; q < queries.cols(); ++q) {
    float best = std::numeric_limits<float>::infinity();
    for (Eigen::Index i = 0; i < points.cols(); ++i) best = std::min(best, SquaredDistance(queries.col(q), points.col(i)));
    const auto k = static_cast<std::size_t>(q);
    ASSERT_GE(index[k], 0);
    ASSERT_LT(index[k], 3000);
    EXPECT_EQ(sq_distance[k], best) << "query " << q;
    EXPECT_EQ(SquaredDistance(queries.col(q), points.col(index[k])), best) << "query " << q;
  }
  EXPECT_EQ(sq_distance[1000], 0.0f);
  EXPECT_THAT((std::vector<int>{10, 20, 2999}), ::testing::Contains(index[1000]));
  EXPECT_EQ(index[1001], 7);

  // A batch answers as the queries one by one; an empty batch empties the outputs.
  for (const Eigen::Index q : {0, 500, 1002}) {
    std::vector<int> one_index;
    std::vector<float> one_distance;
    nn.Find(queries.col(q), one_index, one_distance);
    ASSERT_EQ(one_index.size(), 1u);
    EXPECT_EQ(one_index[0], index[static_cast<std::size_t>(q)]);
    EXPECT_EQ(one_distance[0], sq_distance[static_cast<std::size_t>(q)]);
  }
  nn.Find(Eigen::Matrix3Xf(3, 0), index, sq_distance);
  EXPECT_TRUE(index.empty());
  EXPECT_TRUE(sq_distance.empty());

  // Copies share the tree and answer alike.
  const NearestNeighbours copy = nn;
  std::vector<int> copy_index;
  std::vector<float> copy_distance;
  copy.Find(queries.col(5), copy_index, copy_distance);
  nn.Find(queries.col(5), index, sq_distance);
  EXPECT_EQ(copy_index, index);
}

TEST(NearestNeighboursTest, BadInputIsNamed) {
  EXPECT_THAT([] { NearestNeighbours nn{Eigen::Matrix3Xf(3, 0)}; },
              ThrowsMessage<std::invalid_argument>(HasSubstr("points is empty")));
  Eigen::Matrix3Xf points = RandomPoints(20, 3);
  points(1, 4) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT([&] { NearestNeighbours nn{points}; },
              ThrowsMessage<std::invalid_argument>(HasSubstr("points has a non-finite coordinate")));
  std::vector<int> index;
  std::vector<float> sq_distance;
  EXPECT_THAT([&] { NearestNeighbours().Find(RandomPoints(2, 4), index, sq_distance); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("point set is empty")));
  const NearestNeighbours nn(RandomPoints(20, 5));
  Eigen::Matrix3Xf queries = RandomPoints(3, 6);
  queries(2, 1) = std::numeric_limits<float>::infinity();
  EXPECT_THAT([&] { nn.Find(queries, index, sq_distance); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("queries has a non-finite coordinate")));
}

}  // namespace
}  // namespace toolbench::perception::internal
