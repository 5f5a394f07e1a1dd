// Tile demand without a GPU: which tiles a view needs, at which level, computed on the CPU by the
// same rule as the renderer's feedback pass. It is what the load test's simulated viewers ask
// for, and it needs no GL (vts::render_core).
//
// simulate_feedback() writes the buffer the GPU feedback pass would write for a scene (packed as
// feedback.hpp describes), pixel for pixel: a grid of ceil(width / k) x ceil(height / k) points
// over the full view (point (i + 0.5, j + 0.5) is the full view's (i + 0.5) * width / fb_w, ...),
// the footprint of footprint.hpp with level offset +log2(width / fb_w) (the feedback pixel is k
// times larger), and level L = ceil(c) with fraction (L - c) * 256. DemandSimulator then reduces
// it with the renderer's own FeedbackProcessor (bias, dedup, ancestors, coarse-first order), so
// the two can only differ where float and double round differently.
//
// Thread safety: simulate_feedback() is pure; a DemandSimulator is not thread-safe (one per
// viewer).
#pragma once

#include <cstdint>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/renderer/feedback.hpp"
#include "vts/renderer/pyramid.hpp"
#include "vts/renderer/scene.hpp"

namespace vts::renderer {

struct DemandOptions {
  int feedback_divisor = 1;  // k, as VirtualTextureOptions::feedback_divisor (1, 2, 4, 8, 16)
  int anisotropy = 1;        // as VirtualTextureOptions::anisotropy: it changes the level
};

// The packed feedback buffer (two words per feedback pixel, rows top to bottom) for `scene` in a
// width x height view of an image of `geometry`. invalid_argument for an empty or larger than
// 16384 viewport, a divisor not in {1, 2, 4, 8, 16}, or anisotropy outside 1 to 16.
Result<std::vector<std::uint32_t>> simulate_feedback(const Scene& scene, const Geometry& geometry,
                                                     int width, int height,
                                                     const DemandOptions& options = {});

class DemandSimulator {
 public:
  // Fails on a geometry with more levels than the renderer addresses, or options out of range.
  static Result<DemandSimulator> create(const Geometry& geometry, DemandOptions options = {});

  // The tiles the view wants (ancestors included, coarse first, as the renderer requests them).
  Result<std::vector<TileRequest>> demand(const Scene& scene, int width, int height,
                                          double bias = 0);
  const FeedbackStats& last_stats() const { return processor_.last_stats(); }
  const Geometry& geometry() const { return geometry_; }
  const DemandOptions& options() const { return options_; }

 private:
  DemandSimulator(const Geometry& geometry, const Pyramid& pyramid, DemandOptions options)
      : geometry_(geometry), options_(options), processor_(pyramid) {}
  Geometry geometry_;
  DemandOptions options_;
  FeedbackProcessor processor_;
  std::vector<std::uint32_t> buffer_;
};

}  // namespace vts::renderer
