// A latency histogram with a fixed relative error (HDR-style log-linear buckets), for the load
// test: cheap to record into from many viewers, exact to merge, and small whatever the range.
//
// Values are non-negative integers (the load test records nanoseconds). Values below
// 2^sub_bucket_bits are counted exactly; above, each power-of-two range [2^k, 2^(k+1)) is split
// into 2^sub_bucket_bits equal buckets, so a bucket's width is at most value / 2^sub_bucket_bits:
// any value a percentile reports is within relative_error() = 2^-sub_bucket_bits of a recorded
// value. Every uint64 value can be recorded; memory is (65 - sub_bucket_bits) * 2^sub_bucket_bits
// counters at most (allocated as values arrive, highest range first needed).
//
// Percentiles follow the nearest-rank definition on the recorded multiset: percentile(p) is the
// smallest recorded value v such that at least p% of the values are <= v, reported as the highest
// value its bucket holds (never below the true value, at most relative_error() above it; the
// exact value when it was recorded exactly). percentile(0) is min(), percentile(100) is max().
// min() and max() are exact.
//
// Thread safety: none; give each viewer its own and merge() them.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include "vts/base/result.hpp"

namespace vts::loadtest {

class LatencyHistogram {
 public:
  // sub_bucket_bits in [1, 16]; 7 gives a relative error of 1/128 (< 0.8%). Out of range is
  // clamped.
  explicit LatencyHistogram(int sub_bucket_bits = 7);

  void record(std::uint64_t value, std::uint64_t count = 1);
  // Adds every count of `other` (merge(*this) doubles every count). invalid_argument (and no
  // change) when the two were made with different sub_bucket_bits, even if `other` is empty, or
  // when their counts sum past 2^64 - 1.
  Status merge(const LatencyHistogram& other);
  void reset();

  std::uint64_t count() const { return count_; }
  std::uint64_t min() const;  // 0 when empty
  std::uint64_t max() const;  // 0 when empty
  double mean() const;        // exact (from the recorded values' sum); 0 when empty
  // p in [0, 100] (clamped; NaN is 0). 0 when empty.
  std::uint64_t percentile(double p) const;
  double relative_error() const;
  int sub_bucket_bits() const { return bits_; }

  // The non-empty buckets in increasing order: (lowest value, highest value, count). These are
  // the bucket's bounds, not the recorded values': the last bucket's high may exceed max().
  struct Bucket {
    std::uint64_t low = 0, high = 0, count = 0;
  };
  std::vector<Bucket> buckets() const;

  // The histogram that buckets() (with min(), max() and mean()) describes: the inverse of reading
  // those, so a histogram written to JSON and read back has the same counts, percentiles, min and
  // max, and its mean to double precision. invalid_argument when a bucket is not one of this
  // sub_bucket_bits' buckets, the buckets are not in increasing order, a count is 0, the counts
  // sum past 2^64 - 1, or min/max lie outside the first/last bucket.
  static Result<LatencyHistogram> from_buckets(int sub_bucket_bits,
                                               const std::vector<Bucket>& buckets,
                                               std::uint64_t min, std::uint64_t max, double mean);

 private:
  int bits_;
  std::vector<std::uint64_t> counts_;  // index = bucket_index(value)
  std::uint64_t count_ = 0;
  std::uint64_t min_ = ~std::uint64_t{0}, max_ = 0;
  long double sum_ = 0;
};

}  // namespace vts::loadtest
