#include "vts/renderer/feedback.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace vts::renderer {

std::optional<TileId> FeedbackProcessor::requested_tile(std::uint32_t word0, std::uint32_t word1,
                                                        double bias) const {
  if (word0 == FeedbackPixel::kEmpty) return std::nullopt;
  const int level = static_cast<int>((word0 >> 24) & 0x1f);
  const std::uint32_t x = word0 & FeedbackPixel::kCoordMask;
  const std::uint32_t y = word1 & FeedbackPixel::kCoordMask;
  const std::int64_t fraction = word1 >> 24;
  // Work in 1/256 of a level so that the rounding is exact and identical on every machine.
  const std::int64_t bias256 = std::llround(std::max(bias, 0.0) * 256.0);
  const std::int64_t v = std::int64_t{level} * 256 - fraction - bias256;
  int wanted = v <= 0 ? 0 : static_cast<int>((v + 255) / 256);  // ceil, never finer than level
  wanted = std::min({wanted, level, pyramid_.max_level()});
  const TileId t{static_cast<std::uint8_t>(wanted), x >> (level - wanted), y >> (level - wanted)};
  if (!pyramid_.exists(t)) return std::nullopt;
  return t;
}

Result<std::vector<TileRequest>> FeedbackProcessor::process(std::span<const std::uint32_t> buffer,
                                                            double bias) {
  if (buffer.size() % 2 != 0)
    return make_error(
        ErrorCode::invalid_argument,
        "feedback buffer of " + std::to_string(buffer.size()) + " words is not made of word pairs");
  stats_ = FeedbackStats{};
  index_.clear();
  std::vector<TileRequest> out;
  const auto add = [&](TileId t, std::uint32_t coverage, bool direct) {
    auto [it, inserted] = index_.try_emplace(tile_key(t), out.size());
    if (inserted) out.push_back(TileRequest{t, 0, false});
    out[it->second].coverage += coverage;
    out[it->second].direct = out[it->second].direct || direct;
  };
  for (std::size_t i = 0; i < buffer.size(); i += 2) {
    ++stats_.pixels;
    if (buffer[i] == FeedbackPixel::kEmpty) {
      ++stats_.empty;
      continue;
    }
    auto t = requested_tile(buffer[i], buffer[i + 1], bias);
    if (!t) {
      ++stats_.dropped;
      continue;
    }
    add(*t, 1, true);
  }
  stats_.direct = out.size();
  // Ancestors of the directly wanted tiles, each getting the coverage of everything below it.
  // Snapshot first: a directly wanted tile may also be an ancestor of another one, and only its
  // own pixels may flow up from it, or its ancestors would count the descendant twice.
  const std::vector<TileRequest> direct(out.begin(), out.end());
  for (const TileRequest& r : direct)
    for (int z = r.tile.z - 1; z >= 0; --z) add(ancestor_at(r.tile, z), r.coverage, false);
  std::sort(out.begin(), out.end(), [](const TileRequest& a, const TileRequest& b) {
    if (a.tile.z != b.tile.z) return a.tile.z < b.tile.z;
    if (a.coverage != b.coverage) return a.coverage > b.coverage;
    if (a.tile.y != b.tile.y) return a.tile.y < b.tile.y;
    return a.tile.x < b.tile.x;
  });
  return out;
}

}  // namespace vts::renderer
