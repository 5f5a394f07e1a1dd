// Numbers for and from the terminal: a one-line progress bar on stderr (only when stderr is a
// terminal: percentage, counts, rate and ETA, redrawn in place), human-readable sizes and
// durations, and the parsers of counts and sizes given as arguments.
#pragma once

#include <chrono>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/protocol/geometry.hpp"

namespace vts::cli {

class ProgressBar {
 public:
  ProgressBar(std::string label, std::string unit, bool enabled);
  ~ProgressBar();
  void update(std::uint64_t done, std::uint64_t total, const std::string& extra = {});
  void finish();  // clears the line

  static bool stderr_is_terminal();

 private:
  std::string label_, unit_;
  bool enabled_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point t0_;
};

std::string human_bytes(std::uint64_t bytes);
std::string human_duration(double seconds);

// Decimal digits only, no sign; false on overflow or anything else.
bool parse_u64(std::string_view s, std::uint64_t& out);

// The index an array job gives this process: the first of $JOB_COMPLETION_INDEX (Kubernetes),
// $SLURM_ARRAY_TASK_ID and $AWS_BATCH_JOB_ARRAY_INDEX that is set; nullopt when none is. A value
// that is not an index is invalid_argument naming the variable and `what` ("shard index").
Result<std::optional<std::uint64_t>> array_job_index(const std::string& what);
// The name of the variable array_job_index() reads ("SLURM_ARRAY_TASK_ID"); "" when none is set.
const char* array_job_index_name();
// "A<sep>B" (--grid CxR, --synthetic WxH), both decimal digits only (no sign) within T's range;
// false otherwise, leaving a and b unchanged.
template <typename T>
bool parse_pair(const std::string& text, char sep, T& a, T& b) {
  const std::size_t at = text.find(sep);
  std::uint64_t x = 0, y = 0;
  if (at == std::string::npos || !parse_u64(std::string_view(text).substr(0, at), x) ||
      !parse_u64(std::string_view(text).substr(at + 1), y) || x > std::numeric_limits<T>::max() ||
      y > std::numeric_limits<T>::max())
    return false;
  a = static_cast<T>(x);
  b = static_cast<T>(y);
  return true;
}
// A positive byte count with an optional binary suffix: 1048576, 512M, 10G, 2GiB, 64KB.
// invalid_argument naming `flag` otherwise.
Result<std::uint64_t> parse_byte_size(const std::string& text, std::string_view flag);
// Levels "A-B" or "A" (one level), A <= B <= Geometry::kMaxZoom.
Result<std::pair<int, int>> parse_level_range(const std::string& text, std::string_view flag);
// x0,y0,x1,y1 in finest-level texels, half-open, non-empty.
Result<TexelRect> parse_texel_rect(const std::string& text, std::string_view flag);
// `count` comma-separated finite numbers (degrees: W,S,E,N or LON,LAT); invalid_argument naming
// `flag` and `form` otherwise.
Result<std::vector<double>> parse_numbers(const std::string& text, std::size_t count,
                                          std::string_view flag, std::string_view form);

}  // namespace vts::cli
