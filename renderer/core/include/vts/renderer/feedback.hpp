// Reduction of the feedback buffer (which tiles, at which level, the last frame wanted) into a
// prioritised request list for the streaming client and the slot cache.
//
// Feedback packing: the feedback pass renders the scene at 1/k of the screen resolution into a
// two-channel R32UI/RG32UI target, two uint32 per pixel (word0, word1):
//   word0 bits  0-23  x of the tile at `level`
//         bits 24-28  level: the finest level the fragment samples, ceil of its continuous level
//         bits 29-31  0 (all-ones word0 = kEmpty: background, nothing textured)
//   word1 bits  0-23  y of the tile at `level`
//         bits 24-31  fraction f: the fragment's continuous level is level - f/256
// The fraction is what lets a half-level bias mean something: with bias b the wanted level
// becomes ceil(level - f/256 - b), so a bias of 0.5 coarsens the half of the fragments that were
// within half a level of the coarser one.
//
// process() then: applies the bias; clamps levels above the pyramid's max level to it; drops
// tiles outside their level's extent (and counts them); deduplicates, counting covered pixels;
// adds every ancestor up to the root (the page table falls back on them, and their coverage is
// the sum of what they back up); and sorts coarse levels first, then larger coverage first, then
// y, x, so the result is deterministic and the most useful fallbacks stream first.
//
// Thread safety: none; the result and stats belong to the caller of process().
#pragma once

#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/renderer/pyramid.hpp"

namespace vts::renderer {

struct FeedbackPixel {
  static constexpr std::uint32_t kEmpty = 0xffffffffu;  // word0 of a background pixel
  static constexpr std::uint32_t kCoordMask = (1u << 24) - 1;

  // Packs like the feedback shader does. level < 32, x, y < 2^24, fraction < 256.
  static void pack(int level, std::uint32_t x, std::uint32_t y, std::uint32_t fraction,
                   std::uint32_t* out) {
    out[0] = (x & kCoordMask) | (std::uint32_t(level & 0x1f) << 24);
    out[1] = (y & kCoordMask) | ((fraction & 0xffu) << 24);
  }
};

struct TileRequest {
  TileId tile;
  std::uint32_t coverage = 0;  // feedback pixels wanting the tile or (for ancestors) a descendant
  bool direct = false;         // true if some pixel wanted exactly this tile
  bool operator==(const TileRequest&) const = default;
};

struct FeedbackStats {
  std::uint64_t pixels = 0;   // pixels read (word pairs)
  std::uint64_t empty = 0;    // background pixels
  std::uint64_t dropped = 0;  // pixels whose tile lies outside the pyramid
  std::uint64_t direct = 0;   // distinct tiles wanted directly
};

class FeedbackProcessor {
 public:
  explicit FeedbackProcessor(const Pyramid& pyramid) : pyramid_(pyramid) {}

  // buffer: word pairs as packed above (any pixel order; its length must be even, else
  // invalid_argument). bias: the global mip bias in levels (>= 0; negative counts as 0).
  Result<std::vector<TileRequest>> process(std::span<const std::uint32_t> buffer, double bias);
  const FeedbackStats& last_stats() const { return stats_; }

  // The level and tile a packed pixel asks for after bias and clamping to the pyramid, for one
  // pixel; nullopt for background or out-of-pyramid. Exposed for tests and the debug overlay.
  std::optional<TileId> requested_tile(std::uint32_t word0, std::uint32_t word1, double bias) const;

 private:
  Pyramid pyramid_;
  FeedbackStats stats_;
  std::unordered_map<std::uint64_t, std::size_t> index_;  // reused between calls
};

}  // namespace vts::renderer
