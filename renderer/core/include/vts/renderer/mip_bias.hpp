// A global mip bias that keeps the tiles a frame demands within what the physical texture holds.
//
// When the feedback asks for more tiles than the slots can hold, the frame cannot be drawn at full
// detail anyway; the alternative to biasing is thrashing (evicting tiles the same frame needs).
// update() is called once per frame with the number of distinct tiles the last feedback demanded
// (measured with the bias then in force) and returns the bias to use next, in levels (multiples of
// `step`, in [0, max_bias]):
//   - demand > capacity * high_watermark raises the bias by one step (at most once every
//     `raise_interval` frames, since feedback lags the bias by a frame or two);
//   - the bias is lowered by one step only after `calm_frames` consecutive frames in which demand
//     was below capacity * low_watermark AND the demand predicted after lowering (demand *
//     growth^step, growth = 4 tiles per level finer on a screen-filling view) would stay at or
//     below capacity * high_watermark. The second condition is what rules out oscillation: without
//     it a view needing 0.5 x capacity at bias 1 would drop to bias 0, demand 2 x capacity, and
//     bounce back up every calm_frames frames.
// Any frame outside the calm condition restarts the count. Thread safety: none.
#pragma once

#include <cstdint>

namespace vts::renderer {

class MipBiasController {
 public:
  struct Options {
    std::uint32_t capacity = 1024;     // slots available for demanded tiles
    double high_watermark = 0.9;       // fraction of capacity above which the bias rises
    double low_watermark = 0.5;        // fraction of capacity below which it may fall
    std::uint32_t calm_frames = 30;    // consecutive calm frames before each step down
    std::uint32_t raise_interval = 1;  // frames between two raises (>= 1)
    double step = 1.0;                 // bias step in levels (1.0 or 0.5)
    double max_bias = 4.0;             // upper bound of the bias
    double growth = 4.0;               // demand factor per level of detail added
  };

  explicit MipBiasController(Options options) : options_(options) {}

  // Feeds one frame's demand; returns the new bias.
  double update(std::uint64_t demanded_tiles);
  double bias() const { return bias_; }
  // Consecutive calm frames counted so far (for tests and the HUD).
  std::uint32_t calm_count() const { return calm_; }

 private:
  Options options_;
  double bias_ = 0.0;
  std::uint32_t calm_ = 0;
  std::uint32_t since_raise_ = ~0u;
};

}  // namespace vts::renderer
