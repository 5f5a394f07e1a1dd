// The payload mix the archive layout rule treats differently (pmtiles_part.hpp), for the tests of
// the writer and the merges: small payloads repeated far apart (uniform tiles), large ones
// repeated far apart and in runs of consecutive ids, unique large ones, and missing tiles.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <random>
#include <vector>

namespace vts::archive::test {

// The payload of tile `id`, drawn from `rng`, given the tiles made so far (a run repeats the
// previous tile's); nullopt: no tile there.
inline std::optional<std::vector<std::uint8_t>> mixed_payload(
    std::mt19937& rng, const std::map<std::uint64_t, std::vector<std::uint8_t>>& tiles,
    std::uint64_t id) {
  static const std::vector<std::uint8_t> big_repeat(3000, 7), small_a(40, 1), small_b(900, 2);
  const unsigned kind = rng() % 10;
  if (kind < 2) return small_a;
  if (kind == 2) return small_b;
  if (kind == 3) return big_repeat;
  if (kind == 4 && !tiles.empty() && tiles.rbegin()->first + 1 == id)
    return tiles.rbegin()->second;  // the same as the tile before: a run
  if (kind == 5) return std::nullopt;
  std::vector<std::uint8_t> b(1100 + rng() % 3000);
  for (auto& v : b) v = static_cast<std::uint8_t>(rng());
  return b;
}

}  // namespace vts::archive::test
