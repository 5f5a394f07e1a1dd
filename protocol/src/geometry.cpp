#include "vts/protocol/geometry.hpp"

#include <algorithm>
#include <charconv>

namespace vts {
inline namespace protocol {

namespace {
std::uint64_t ceil_shift(std::uint64_t v, int shift) {
  return shift >= 64 ? (v ? 1 : 0) : (v + ((std::uint64_t{1} << shift) - 1)) >> shift;
}
std::uint64_t ceil_div(std::uint64_t a, std::uint64_t b) {
  return (a + b - 1) / b;
}
bool is_pow2(std::uint64_t v) {
  return v && !(v & (v - 1));
}
}  // namespace

std::string TileId::to_string() const {
  return std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y);
}

Result<TileId> parse_tile_id(std::string_view text) {
  std::uint64_t parts[3] = {0, 0, 0};
  std::size_t pos = 0;
  for (int i = 0; i < 3; ++i) {
    std::size_t end = i < 2 ? text.find('/', pos) : text.size();
    if (end == std::string_view::npos) end = text.size();
    std::string_view part = text.substr(pos, end - pos);
    auto [p, ec] = std::from_chars(part.data(), part.data() + part.size(), parts[i]);
    if (part.empty() || ec != std::errc() || p != part.data() + part.size())
      return make_error(ErrorCode::invalid_argument,
                        "tile id '" + std::string(text) + "' is not of the form z/x/y");
    pos = end + 1;
    if (i < 2 && end == text.size())
      return make_error(ErrorCode::invalid_argument,
                        "tile id '" + std::string(text) + "' is not of the form z/x/y");
  }
  if (parts[0] > 31 || parts[1] >= (std::uint64_t{1} << parts[0]) ||
      parts[2] >= (std::uint64_t{1} << parts[0]))
    return make_error(ErrorCode::invalid_argument,
                      "tile id '" + std::string(text) + "' is out of range for its level");
  return TileId{static_cast<std::uint8_t>(parts[0]), static_cast<std::uint32_t>(parts[1]),
                static_cast<std::uint32_t>(parts[2])};
}

Result<Geometry> Geometry::create(std::uint64_t width, std::uint64_t height,
                                  std::uint32_t tile_size, std::uint32_t border) {
  if (width == 0 || height == 0)
    return make_error(ErrorCode::invalid_argument, "image size " + std::to_string(width) + "x" +
                                                       std::to_string(height) + " is empty");
  if (!is_pow2(tile_size) || tile_size < kMinTileSize || tile_size > kMaxTileSize)
    return make_error(ErrorCode::invalid_argument,
                      "tile size " + std::to_string(tile_size) + " must be a power of two in [" +
                          std::to_string(kMinTileSize) + ", " + std::to_string(kMaxTileSize) + "]");
  if (border > tile_size / 2)
    return make_error(ErrorCode::invalid_argument, "border " + std::to_string(border) +
                                                       " exceeds half the tile size " +
                                                       std::to_string(tile_size));
  const std::uint64_t extent = std::max(width, height);
  int mz = 0;
  while ((std::uint64_t{tile_size} << mz) < extent) {
    ++mz;
    if (mz > kMaxZoom)
      return make_error(ErrorCode::invalid_argument,
                        "image " + std::to_string(width) + "x" + std::to_string(height) +
                            " needs more than " + std::to_string(kMaxZoom) + " levels of " +
                            std::to_string(tile_size) + "-texel tiles");
  }
  return Geometry(width, height, tile_size, border, mz);
}

std::uint64_t Geometry::level_width(int z) const {
  assert(valid_level(z));
  return ceil_shift(width_, max_zoom_ - z);
}
std::uint64_t Geometry::level_height(int z) const {
  assert(valid_level(z));
  return ceil_shift(height_, max_zoom_ - z);
}
std::uint32_t Geometry::tiles_x(int z) const {
  return static_cast<std::uint32_t>(ceil_div(level_width(z), tile_));
}
std::uint32_t Geometry::tiles_y(int z) const {
  return static_cast<std::uint32_t>(ceil_div(level_height(z), tile_));
}
std::uint64_t Geometry::total_tile_count() const {
  std::uint64_t n = 0;
  for (int z = 0; z <= max_zoom_; ++z) n += tile_count(z);
  return n;
}

bool Geometry::exists(TileId t) const {
  return valid_level(t.z) && t.x < tiles_x(t.z) && t.y < tiles_y(t.z);
}

std::vector<TileId> ancestors(TileId t) {
  std::vector<TileId> out;
  out.reserve(t.z);
  for (int z = t.z - 1; z >= 0; --z) out.push_back(ancestor_at(t, z));
  return out;
}

std::optional<TileId> Geometry::parent(TileId t) const {
  if (t.z == 0) return std::nullopt;
  return TileId{static_cast<std::uint8_t>(t.z - 1), t.x >> 1, t.y >> 1};
}

std::vector<TileId> Geometry::children(TileId t) const {
  std::vector<TileId> out;
  if (t.z >= max_zoom_) return out;
  const auto cz = static_cast<std::uint8_t>(t.z + 1);
  for (std::uint32_t dy = 0; dy < 2; ++dy)
    for (std::uint32_t dx = 0; dx < 2; ++dx) {
      TileId c{cz, 2 * t.x + dx, 2 * t.y + dy};
      if (exists(c)) out.push_back(c);
    }
  return out;
}

TexelRect Geometry::content_slot(TileId t) const {
  return {std::uint64_t{t.x} * tile_, std::uint64_t{t.y} * tile_, (std::uint64_t{t.x} + 1) * tile_,
          (std::uint64_t{t.y} + 1) * tile_};
}

TexelRect Geometry::content_rect(TileId t) const {
  TexelRect r = content_slot(t);
  r.x1 = std::min(r.x1, level_width(t.z));
  r.y1 = std::min(r.y1, level_height(t.z));
  r.x0 = std::min(r.x0, r.x1);
  r.y0 = std::min(r.y0, r.y1);
  return r;
}

TileId Geometry::tile_of_texel(int z, std::uint64_t px, std::uint64_t py) const {
  assert(valid_level(z) && px < level_width(z) && py < level_height(z));
  return TileId{static_cast<std::uint8_t>(z), static_cast<std::uint32_t>(px / tile_),
                static_cast<std::uint32_t>(py / tile_)};
}

namespace {
std::uint64_t clamp_coord(std::int64_t v, std::uint64_t extent) {
  if (v < 0) return 0;
  return std::min<std::uint64_t>(static_cast<std::uint64_t>(v), extent - 1);
}
}  // namespace

std::uint64_t Geometry::stored_to_level_x(TileId t, std::uint32_t sx) const {
  const auto v = static_cast<std::int64_t>(std::uint64_t{t.x} * tile_) - border_ + sx;
  return clamp_coord(v, level_width(t.z));
}
std::uint64_t Geometry::stored_to_level_y(TileId t, std::uint32_t sy) const {
  const auto v = static_cast<std::int64_t>(std::uint64_t{t.y} * tile_) - border_ + sy;
  return clamp_coord(v, level_height(t.z));
}

TexelRect Geometry::map_rect(int from_z, const TexelRect& rect, int to_z) const {
  assert(valid_level(from_z) && valid_level(to_z));
  TexelRect r = rect;
  if (to_z < from_z) {
    const int s = from_z - to_z;
    r = {rect.x0 >> s, rect.y0 >> s, ceil_shift(rect.x1, s), ceil_shift(rect.y1, s)};
  } else if (to_z > from_z) {
    const int s = to_z - from_z;
    r = {rect.x0 << s, rect.y0 << s, rect.x1 << s, rect.y1 << s};
  }
  r.x1 = std::min(r.x1, level_width(to_z));
  r.y1 = std::min(r.y1, level_height(to_z));
  r.x0 = std::min(r.x0, r.x1);
  r.y0 = std::min(r.y0, r.y1);
  return r;
}

}  // namespace protocol
}  // namespace vts
