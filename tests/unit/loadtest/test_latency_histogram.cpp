#include "vts/loadtest/latency_histogram.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace vts::loadtest {
namespace {

constexpr std::uint64_t kMax = std::numeric_limits<std::uint64_t>::max();

// Percentiles as ten-thousandths, so the reference rank is exact integer arithmetic.
constexpr std::uint64_t kPercentilesE4[] = {1,      10000,  100000, 250000, 500000, 750000,
                                            900000, 950000, 990000, 999000, 999900, 999990};

// The nearest-rank percentile of `sorted` (ascending, non-empty): the value at rank
// ceil(p / 100 * n), rank at least 1.
std::uint64_t exact_percentile(const std::vector<std::uint64_t>& sorted, std::uint64_t p_e4) {
  const std::uint64_t n = sorted.size();
  std::uint64_t rank = (p_e4 * n + 999999) / 1000000;
  rank = std::clamp<std::uint64_t>(rank, 1, n);
  return sorted[rank - 1];
}

// The histogram's answer must be the exact value or at most relative_error() above it.
void expect_within_relative_error(const LatencyHistogram& h, std::vector<std::uint64_t> values,
                                  const std::string& what) {
  std::sort(values.begin(), values.end());
  for (std::uint64_t p_e4 : kPercentilesE4) {
    const double p = static_cast<double>(p_e4) / 10000.0;
    const std::uint64_t truth = exact_percentile(values, p_e4);
    const std::uint64_t got = h.percentile(p);
    SCOPED_TRACE(what + " p" + std::to_string(p) + " bits " + std::to_string(h.sub_bucket_bits()));
    EXPECT_GE(got, truth);
    // got - truth <= truth * 2^-bits, written so that it cannot overflow near UINT64_MAX.
    EXPECT_LE(got - truth, truth >> h.sub_bucket_bits());
    EXPECT_LE(static_cast<double>(got - truth), static_cast<double>(truth) * h.relative_error());
    if (truth < (std::uint64_t{1} << h.sub_bucket_bits())) {
      EXPECT_EQ(got, truth);
    }
  }
  EXPECT_EQ(h.percentile(0), values.front());
  EXPECT_EQ(h.percentile(100), values.back());
  EXPECT_EQ(h.min(), values.front());
  EXPECT_EQ(h.max(), values.back());
}

// Data sets shaped like what the load test measures, in nanoseconds.
std::vector<std::uint64_t> data_set(const std::string& name, std::size_t n, std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<std::uint64_t> v(n);
  if (name == "small_exact") {
    std::uniform_int_distribution<std::uint64_t> d(0, 300);
    for (auto& x : v) x = d(rng);
  } else if (name == "log_uniform_ns_to_minutes") {
    // 1 ns .. 10 min, every decade equally likely.
    std::uniform_real_distribution<double> d(0.0, std::log(600e9));
    for (auto& x : v) x = static_cast<std::uint64_t>(std::exp(d(rng)));
  } else if (name == "lognormal") {
    std::lognormal_distribution<double> d(std::log(2e6), 1.5);  // median 2 ms
    for (auto& x : v) x = static_cast<std::uint64_t>(std::min(d(rng), 1e18));
  } else if (name == "pareto_heavy_tail") {
    // Pareto with alpha 0.7 from 50 us: infinite mean, a few values in the hours.
    std::uniform_real_distribution<double> d(0.0, 1.0);
    for (auto& x : v) {
      x = static_cast<std::uint64_t>(std::min(50e3 / std::pow(1.0 - d(rng), 1.0 / 0.7), 1e16));
    }
  } else if (name == "bimodal_cache_hits_and_network") {
    std::normal_distribution<double> ram(40e3, 5e3), net(35e6, 10e6);
    std::bernoulli_distribution hit(0.8);
    for (auto& x : v) x = static_cast<std::uint64_t>(std::max(1.0, hit(rng) ? ram(rng) : net(rng)));
  } else if (name == "exponential") {
    std::exponential_distribution<double> d(1.0 / 5e6);
    for (auto& x : v) x = static_cast<std::uint64_t>(d(rng));
  } else if (name == "near_uint64_max") {
    std::uniform_int_distribution<std::uint64_t> d(kMax - (std::uint64_t{1} << 62), kMax);
    for (auto& x : v) x = d(rng);
    v[0] = kMax;
  } else {
    ADD_FAILURE() << "unknown data set " << name;
  }
  return v;
}

const char* const kDataSets[] = {
    "small_exact",       "log_uniform_ns_to_minutes",      "lognormal",
    "pareto_heavy_tail", "bimodal_cache_hits_and_network", "exponential",
    "near_uint64_max",
};

TEST(LatencyHistogram, PercentilesMatchAnExactSortWithinTheRelativeError) {
  for (int bits : {1, 3, 5, 7, 10, 16}) {
    for (const char* name : kDataSets) {
      const auto values = data_set(name, 20011, 1234u + static_cast<std::uint32_t>(bits));
      LatencyHistogram h(bits);
      for (std::uint64_t x : values) h.record(x);
      ASSERT_EQ(h.count(), values.size());
      expect_within_relative_error(h, values, name);
    }
  }
}

TEST(LatencyHistogram, SmallDataSetsAndEveryRankAreExact) {
  // Values below 2^bits are exact, so every percentile of them is the exact nearest rank.
  LatencyHistogram h(7);
  const std::vector<std::uint64_t> values = {5, 1, 3, 2, 4, 0, 127, 64, 3, 3};
  for (std::uint64_t x : values) h.record(x);
  std::vector<std::uint64_t> sorted = values;
  std::sort(sorted.begin(), sorted.end());
  for (std::uint64_t p_e4 = 0; p_e4 <= 1000000; p_e4 += 2500) {
    const double p = static_cast<double>(p_e4) / 10000.0;
    const std::uint64_t expected = p_e4 == 0 ? sorted.front() : exact_percentile(sorted, p_e4);
    EXPECT_EQ(h.percentile(p), expected) << "p" << p;
  }
  // The nearest rank: 10 values, p50 is the 5th (3), p51 the 6th (3), p90 the 9th (64).
  EXPECT_EQ(h.percentile(50), 3u);
  EXPECT_EQ(h.percentile(90), 64u);
  EXPECT_EQ(h.percentile(90.0001), 127u);
}

TEST(LatencyHistogram, NinetyNinePointNineOfAThousandIsTheNineHundredNinetyNinth) {
  // 99.9 is not exact in binary; the rank must still be 999, not 1000.
  LatencyHistogram h(7);
  for (std::uint64_t i = 1; i <= 1000; ++i) h.record(i * 1000);
  const std::uint64_t got = h.percentile(99.9);
  EXPECT_GE(got, 999000u);
  EXPECT_LT(got, 1000000u);
  EXPECT_EQ(h.percentile(100), 1000000u);
}

TEST(LatencyHistogram, ARecordedCountActsAsThatManyRecords) {
  LatencyHistogram once(7), many(7);
  once.record(12345, 1000);
  once.record(7, 3);
  for (int i = 0; i < 1000; ++i) many.record(12345);
  for (int i = 0; i < 3; ++i) many.record(7);
  EXPECT_EQ(once.count(), 1003u);
  EXPECT_EQ(once.mean(), many.mean());
  for (double p : {0.0, 0.1, 0.3, 0.4, 50.0, 100.0})
    EXPECT_EQ(once.percentile(p), many.percentile(p));
  // A count of zero records nothing, not even a min or max.
  LatencyHistogram none(7);
  none.record(99, 0);
  EXPECT_EQ(none.count(), 0u);
  EXPECT_EQ(none.max(), 0u);
  EXPECT_TRUE(none.buckets().empty());
}

TEST(LatencyHistogram, MergingManyEqualsRecordingEverythingInOne) {
  for (const char* name : kDataSets) {
    const auto values = data_set(name, 30000, 99);
    LatencyHistogram all(7);
    std::vector<LatencyHistogram> parts(8, LatencyHistogram(7));
    std::mt19937 rng(5);
    std::uniform_int_distribution<std::size_t> pick(0, parts.size() - 2);  // the last stays empty
    for (std::uint64_t x : values) {
      all.record(x);
      parts[pick(rng)].record(x);
    }
    LatencyHistogram merged(7);
    for (const auto& part : parts) ASSERT_TRUE(merged.merge(part).ok());
    SCOPED_TRACE(name);
    EXPECT_EQ(merged.count(), all.count());
    EXPECT_EQ(merged.min(), all.min());
    EXPECT_EQ(merged.max(), all.max());
    EXPECT_EQ(merged.mean(), all.mean());
    const auto a = all.buckets(), b = merged.buckets();
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].low, b[i].low);
      EXPECT_EQ(a[i].high, b[i].high);
      EXPECT_EQ(a[i].count, b[i].count);
    }
    for (std::uint64_t p_e4 : kPercentilesE4) {
      const double p = static_cast<double>(p_e4) / 10000.0;
      EXPECT_EQ(merged.percentile(p), all.percentile(p));
    }
  }
}

TEST(LatencyHistogram, MergingIntoItselfDoublesEveryCount) {
  LatencyHistogram h(7);
  for (std::uint64_t x : {3u, 1000u, 5000000u}) h.record(x);
  ASSERT_TRUE(h.merge(h).ok());
  EXPECT_EQ(h.count(), 6u);
  for (const auto& b : h.buckets()) EXPECT_EQ(b.count, 2u);
  EXPECT_EQ(h.min(), 3u);
  EXPECT_EQ(h.max(), 5000000u);
}

TEST(LatencyHistogram, MergeWithDifferentSubBucketBitsIsRefusedAndChangesNothing) {
  LatencyHistogram a(7), b(8);
  a.record(100);
  b.record(1000000);
  const Status s = a.merge(b);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(s.error().message.find("sub-bucket bits"), std::string::npos);
  EXPECT_EQ(a.count(), 1u);
  EXPECT_EQ(a.max(), 100u);
  // Even an empty histogram of other bits is refused: the caller mixed up configurations.
  EXPECT_FALSE(a.merge(LatencyHistogram(6)).ok());
}

TEST(LatencyHistogram, MinMaxAndMeanAreExact) {
  LatencyHistogram h(3);  // coarse buckets: min, max and mean must not come from them
  const std::vector<std::uint64_t> values = {1000003, 77777777, 123456789, 999, 5};
  long double sum = 0;
  for (std::uint64_t x : values) {
    h.record(x);
    sum += static_cast<long double>(x);
  }
  EXPECT_EQ(h.min(), 5u);
  EXPECT_EQ(h.max(), 123456789u);
  EXPECT_EQ(h.mean(), static_cast<double>(sum / 5));
  EXPECT_EQ(h.percentile(0), 5u);
  EXPECT_EQ(h.percentile(100), 123456789u);
  // A bucket's top can lie above max(); percentiles never report past max().
  EXPECT_LE(h.percentile(99.99), 123456789u);
}

TEST(LatencyHistogram, HugeValuesUpToUint64MaxAreRecorded) {
  for (int bits : {1, 7, 16}) {
    LatencyHistogram h(bits);
    h.record(kMax);
    h.record(kMax - 1);
    h.record(std::uint64_t{1} << 63);
    h.record((std::uint64_t{1} << 63) - 1);
    h.record(0);
    SCOPED_TRACE(bits);
    EXPECT_EQ(h.count(), 5u);
    EXPECT_EQ(h.max(), kMax);
    EXPECT_EQ(h.min(), 0u);
    EXPECT_EQ(h.percentile(100), kMax);
    EXPECT_GE(h.percentile(80), kMax - 1);
    EXPECT_GE(h.percentile(60), std::uint64_t{1} << 63);
    EXPECT_EQ(h.percentile(20), 0u);
    const auto buckets = h.buckets();
    ASSERT_FALSE(buckets.empty());
    EXPECT_EQ(buckets.back().high, kMax);
    EXPECT_LE(buckets.back().low, kMax - 1);
    std::uint64_t total = 0;
    for (const auto& b : buckets) total += b.count;
    EXPECT_EQ(total, 5u);
    EXPECT_NEAR(h.mean(), (2.0 * 18446744073709551615.0 + 2.0 * 9223372036854775808.0) / 5.0, 1e6);
  }
  LatencyHistogram one(7);
  one.record(kMax, 3);
  EXPECT_EQ(one.mean(), static_cast<double>(kMax));
}

TEST(LatencyHistogram, BucketsTileTheValueRangeWithBoundedWidth) {
  for (int bits : {1, 2, 7, 16}) {
    LatencyHistogram h(bits);
    // One value in every power-of-two range, at its start and end, and some values between.
    for (int k = 0; k < 64; ++k) {
      const std::uint64_t lo = std::uint64_t{1} << k;
      h.record(lo);
      h.record(lo + (lo - 1));
      h.record(lo + lo / 3);
    }
    h.record(0);
    std::uint64_t previous_high = 0;
    bool first = true;
    for (const auto& b : h.buckets()) {
      SCOPED_TRACE(b.low);
      EXPECT_LE(b.low, b.high);
      if (!first) {
        EXPECT_GT(b.low, previous_high);
      }
      first = false;
      previous_high = b.high;
      // width - 1 <= low * 2^-bits: the relative error bound.
      EXPECT_LE(b.high - b.low, b.low >> bits);
    }
  }
}

TEST(LatencyHistogram, EmptyReportsZeroEverywhere) {
  LatencyHistogram h;
  EXPECT_EQ(h.sub_bucket_bits(), 7);
  EXPECT_EQ(h.relative_error(), 1.0 / 128);
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.min(), 0u);
  EXPECT_EQ(h.max(), 0u);
  EXPECT_EQ(h.mean(), 0.0);
  EXPECT_EQ(h.percentile(50), 0u);
  EXPECT_EQ(h.percentile(100), 0u);
  EXPECT_TRUE(h.buckets().empty());
  LatencyHistogram other;
  EXPECT_TRUE(h.merge(other).ok());
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.max(), 0u);
}

TEST(LatencyHistogram, ResetForgetsEverything) {
  LatencyHistogram h;
  h.record(kMax);
  h.record(5);
  h.reset();
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.min(), 0u);
  EXPECT_EQ(h.max(), 0u);
  EXPECT_EQ(h.mean(), 0.0);
  EXPECT_TRUE(h.buckets().empty());
  h.record(42);
  EXPECT_EQ(h.min(), 42u);
  EXPECT_EQ(h.max(), 42u);
  EXPECT_EQ(h.mean(), 42.0);
}

TEST(LatencyHistogram, PercentileArgumentIsClampedAndNanIsZero) {
  LatencyHistogram h;
  for (std::uint64_t x = 10; x <= 1000; x += 10) h.record(x);
  EXPECT_EQ(h.percentile(std::numeric_limits<double>::quiet_NaN()), 10u);
  EXPECT_EQ(h.percentile(-5), 10u);
  EXPECT_EQ(h.percentile(-std::numeric_limits<double>::infinity()), 10u);
  EXPECT_EQ(h.percentile(250), 1000u);
  EXPECT_EQ(h.percentile(std::numeric_limits<double>::infinity()), 1000u);
  // The smallest positive p is rank 1, the minimum (reported as its bucket's top).
  EXPECT_GE(h.percentile(1e-300), 10u);
  EXPECT_LE(h.percentile(1e-300), 10u + 10u / 128u);
}

TEST(LatencyHistogram, SubBucketBitsOutOfRangeAreClamped) {
  EXPECT_EQ(LatencyHistogram(0).sub_bucket_bits(), 1);
  EXPECT_EQ(LatencyHistogram(-3).sub_bucket_bits(), 1);
  EXPECT_EQ(LatencyHistogram(17).sub_bucket_bits(), 16);
  EXPECT_EQ(LatencyHistogram(1000).relative_error(), 1.0 / 65536);
}

}  // namespace
}  // namespace vts::loadtest
