// A one-line progress bar on stderr (only when stderr is a terminal): percentage, counts, rate and
// ETA, redrawn in place at most ten times a second.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

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

}  // namespace vts::cli
