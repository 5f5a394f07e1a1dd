// Log-linear buckets: index i < 2^bits holds the value i exactly; above, the value v with highest
// set bit k (k >= bits) falls in bucket (k - bits) * 2^bits + (v >> (k - bits)), whose width is
// 2^(k - bits). The top bucket (k = 63) has index (65 - bits) * 2^bits - 1.
#include "vts/loadtest/latency_histogram.hpp"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <string>

namespace vts::loadtest {
namespace {

constexpr int kMinBits = 1;
constexpr int kMaxBits = 16;

std::size_t bucket_index(std::uint64_t value, int bits) {
  if (value < (std::uint64_t{1} << bits)) return static_cast<std::size_t>(value);
  const int k = 63 - std::countl_zero(value);
  const int shift = k - bits;
  return (static_cast<std::size_t>(shift) << bits) + static_cast<std::size_t>(value >> shift);
}

// Lowest and highest value bucket `index` holds.
std::pair<std::uint64_t, std::uint64_t> bucket_range(std::size_t index, int bits) {
  if (index < (std::size_t{1} << bits)) return {index, index};
  const int shift = static_cast<int>(index >> bits) - 1;
  const std::uint64_t mantissa = index - (static_cast<std::uint64_t>(shift) << bits);
  const std::uint64_t low = mantissa << shift;
  // low + (2^shift - 1) cannot overflow: the top bucket ends exactly at UINT64_MAX.
  return {low, low + ((std::uint64_t{1} << shift) - 1)};
}

// The nearest rank of percentile p (in (0, 100]) among `count` values: ceil(p / 100 * count),
// in [1, count]. p arrives as a binary double (99.9 is 99.900000000000006), so a product a few ulps
// above an integer is taken as that integer; otherwise p = 99.9 of 1000 values would be rank 1000.
std::uint64_t nearest_rank(double p, std::uint64_t count) {
  const long double x = static_cast<long double>(p) / 100.0L * static_cast<long double>(count);
  const long double rank = std::ceil(x - x * 1e-12L);
  if (!(rank >= 1.0L)) return 1;
  if (rank >= static_cast<long double>(count)) return count;
  return static_cast<std::uint64_t>(rank);
}

}  // namespace

LatencyHistogram::LatencyHistogram(int sub_bucket_bits)
    : bits_(std::clamp(sub_bucket_bits, kMinBits, kMaxBits)) {}

void LatencyHistogram::record(std::uint64_t value, std::uint64_t count) {
  if (count == 0) return;
  const std::size_t index = bucket_index(value, bits_);
  if (index >= counts_.size()) counts_.resize(index + 1, 0);
  counts_[index] += count;
  count_ += count;
  min_ = std::min(min_, value);
  max_ = std::max(max_, value);
  sum_ += static_cast<long double>(value) * static_cast<long double>(count);
}

Status LatencyHistogram::merge(const LatencyHistogram& other) {
  if (other.bits_ != bits_) {
    return make_error(ErrorCode::invalid_argument,
                      "cannot merge a latency histogram with " + std::to_string(other.bits_) +
                          " sub-bucket bits into one with " + std::to_string(bits_));
  }
  if (other.count_ == 0) return {};
  // No bucket holds more than the count, so a count that fits means every bucket's sum fits.
  std::uint64_t count;
  if (__builtin_add_overflow(count_, other.count_, &count)) {
    return make_error(ErrorCode::invalid_argument,
                      "cannot merge latency histograms whose counts sum past 2^64 - 1");
  }
  if (other.counts_.size() > counts_.size()) counts_.resize(other.counts_.size(), 0);
  // Indexing (not iterators) keeps merge(*this) correct: it doubles every count.
  for (std::size_t i = 0; i < other.counts_.size(); ++i) counts_[i] += other.counts_[i];
  count_ = count;
  min_ = std::min(min_, other.min_);
  max_ = std::max(max_, other.max_);
  sum_ += other.sum_;
  return {};
}

void LatencyHistogram::reset() {
  counts_.clear();
  count_ = 0;
  min_ = ~std::uint64_t{0};
  max_ = 0;
  sum_ = 0;
}

std::uint64_t LatencyHistogram::min() const {
  return count_ == 0 ? 0 : min_;
}

std::uint64_t LatencyHistogram::max() const {
  return count_ == 0 ? 0 : max_;
}

double LatencyHistogram::mean() const {
  if (count_ == 0) return 0.0;
  return static_cast<double>(sum_ / static_cast<long double>(count_));
}

std::uint64_t LatencyHistogram::percentile(double p) const {
  if (count_ == 0) return 0;
  if (std::isnan(p) || p <= 0.0) return min_;
  if (p >= 100.0) return max_;
  const std::uint64_t rank = nearest_rank(p, count_);
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < counts_.size(); ++i) {
    seen += counts_[i];
    if (seen >= rank) {
      // The bucket's top can lie above every recorded value; max() is the tighter bound there.
      return std::min(bucket_range(i, bits_).second, max_);
    }
  }
  assert(false && "bucket counts sum to less than count()");
  return max_;
}

double LatencyHistogram::relative_error() const {
  return std::ldexp(1.0, -bits_);
}

std::vector<LatencyHistogram::Bucket> LatencyHistogram::buckets() const {
  std::vector<Bucket> out;
  for (std::size_t i = 0; i < counts_.size(); ++i) {
    if (counts_[i] == 0) continue;
    const auto [low, high] = bucket_range(i, bits_);
    out.push_back(Bucket{low, high, counts_[i]});
  }
  return out;
}

Result<LatencyHistogram> LatencyHistogram::from_buckets(int sub_bucket_bits,
                                                        const std::vector<Bucket>& buckets,
                                                        std::uint64_t min, std::uint64_t max,
                                                        double mean) {
  auto bad = [](const std::string& why) -> Result<LatencyHistogram> {
    return make_error(ErrorCode::invalid_argument, "latency histogram: " + why);
  };
  if (sub_bucket_bits < kMinBits || sub_bucket_bits > kMaxBits)
    return bad("sub_bucket_bits " + std::to_string(sub_bucket_bits) + " is not in [1, 16]");
  LatencyHistogram h(sub_bucket_bits);
  std::size_t next = 0;  // the lowest index the next bucket may have
  for (const Bucket& b : buckets) {
    const std::size_t index = bucket_index(b.low, sub_bucket_bits);
    if (bucket_range(index, sub_bucket_bits) != std::pair{b.low, b.high})
      return bad("[" + std::to_string(b.low) + ", " + std::to_string(b.high) + "] is not a bucket");
    if (index < next) return bad("buckets out of order at " + std::to_string(b.low));
    if (b.count == 0) return bad("bucket at " + std::to_string(b.low) + " has count 0");
    if (__builtin_add_overflow(h.count_, b.count, &h.count_))
      return bad("the bucket counts sum past 2^64 - 1 (at " + std::to_string(b.low) + ")");
    if (index >= h.counts_.size()) h.counts_.resize(index + 1, 0);
    h.counts_[index] = b.count;
    next = index + 1;
  }
  if (h.count_ == 0) return h;
  if (min < buckets.front().low || min > buckets.front().high || max < buckets.back().low ||
      max > buckets.back().high || !std::isfinite(mean))
    return bad("min " + std::to_string(min) + " or max " + std::to_string(max) +
               " outside the buckets");
  h.min_ = min;
  h.max_ = max;
  h.sum_ = static_cast<long double>(mean) * static_cast<long double>(h.count_);
  return h;
}

}  // namespace vts::loadtest
