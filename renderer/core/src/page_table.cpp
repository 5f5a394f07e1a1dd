#include "vts/renderer/page_table.hpp"

#include <algorithm>
#include <string>

namespace vts::renderer {

Result<ClipmapPageTable> ClipmapPageTable::create(const Pyramid& pyramid, Options options) {
  const std::uint32_t w = options.window;
  if (w == 0 || w > 4096 || (w & (w - 1)))
    return make_error(ErrorCode::invalid_argument, "page-table window " + std::to_string(w) +
                                                       " must be a power of two in [1, 4096]");
  return ClipmapPageTable(pyramid, w);
}

ClipmapPageTable::ClipmapPageTable(const Pyramid& pyramid, std::uint32_t w)
    : pyramid_(pyramid),
      w_(w),
      mask_(w - 1),
      cells_(std::size_t(kMaxLevels) * w * w, 0),
      shown_(cells_.size(), 0),
      dirty_(cells_.size(), 0),
      layer_dirty_(kMaxLevels, 0) {}

bool ClipmapPageTable::contains(TileId t) const {
  if (!pyramid_.exists(t)) return false;
  // Unsigned subtraction: tiles left of / above the origin wrap to huge values.
  return t.x - ox_[t.z] < w_ && t.y - oy_[t.z] < w_;
}

std::optional<PageEntry> ClipmapPageTable::entry(TileId t) const {
  if (!contains(t)) return std::nullopt;
  return PageEntry::unpack(cells_[(std::size_t(t.z) * w_ + (t.y & mask_)) * w_ + (t.x & mask_)]);
}

bool ClipmapPageTable::is_mapped(TileId t) const {
  return resident_.count(tile_key(t)) != 0;
}

std::uint32_t ClipmapPageTable::resolve_packed(TileId t) const {
  for (int z = t.z; z >= 0; --z) {
    auto it = resident_.find(tile_key(ancestor_at(t, z)));
    if (it != resident_.end()) return PageEntry::pack(it->second, z);
  }
  return 0;
}

std::optional<PageEntry> ClipmapPageTable::resolve(TileId t) const {
  if (!pyramid_.exists(t)) return std::nullopt;
  return PageEntry::unpack(resolve_packed(t));
}

std::span<const std::uint32_t> ClipmapPageTable::layer(int z) const {
  if (z < 0 || z >= kMaxLevels) return {};
  return std::span<const std::uint32_t>(cells_).subspan(std::size_t(z) * w_ * w_,
                                                        std::size_t(w_) * w_);
}

void ClipmapPageTable::write(int z, std::uint32_t x, std::uint32_t y, std::uint32_t value) {
  const std::size_t i = (std::size_t(z) * w_ + (y & mask_)) * w_ + (x & mask_);
  if (cells_[i] == value) return;
  cells_[i] = value;
  dirty_[i] = 1;
  layer_dirty_[z] = 1;
}

template <typename Fn>
void ClipmapPageTable::for_each_window_descendant(TileId t, Fn&& fn) {
  // Bounded by the windows, not by the subtree: at most W^2 cells per level below t, whatever the
  // virtual size. Windows are not assumed nested (each level recenters on its own).
  for (int z = t.z; z <= pyramid_.max_level(); ++z) {
    const int d = z - t.z;
    const std::uint64_t x0 = std::max<std::uint64_t>(std::uint64_t{t.x} << d, ox_[z]);
    const std::uint64_t y0 = std::max<std::uint64_t>(std::uint64_t{t.y} << d, oy_[z]);
    const std::uint64_t x1 = std::min<std::uint64_t>(
        {(std::uint64_t{t.x} + 1) << d, std::uint64_t{ox_[z]} + w_, pyramid_.tiles_x(z)});
    const std::uint64_t y1 = std::min<std::uint64_t>(
        {(std::uint64_t{t.y} + 1) << d, std::uint64_t{oy_[z]} + w_, pyramid_.tiles_y(z)});
    for (std::uint64_t y = y0; y < y1; ++y)
      for (std::uint64_t x = x0; x < x1; ++x)
        fn(z, static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(y));
  }
}

Status ClipmapPageTable::map(TileId t, std::uint32_t slot) {
  if (!pyramid_.exists(t))
    return make_error(ErrorCode::invalid_argument,
                      "tile " + t.to_string() + " is not in the pyramid");
  if (slot > PageEntry::kMaxSlot)
    return make_error(ErrorCode::invalid_argument,
                      "slot " + std::to_string(slot) + " does not fit a page-table entry");
  if (t.z != 0 && !is_mapped(TileId{}))
    return make_error(ErrorCode::invalid_argument,
                      "tile " + t.to_string() + " mapped before the root");
  resident_[tile_key(t)] = slot;
  const std::uint32_t value = PageEntry::pack(slot, t.z);
  for_each_window_descendant(t, [&](int z, std::uint32_t x, std::uint32_t y) {
    const std::uint32_t cur = cell(z, x, y);
    // A descendant already served by a finer resident tile keeps it; one served by a coarser
    // ancestor (or by t's previous slot) now gets t.
    auto e = PageEntry::unpack(cur);
    if (!e || e->level <= t.z) write(z, x, y, value);
  });
  return {};
}

Status ClipmapPageTable::unmap(TileId t) {
  auto it = resident_.find(tile_key(t));
  if (it == resident_.end()) return {};
  if (t.z == 0 && resident_.size() > 1)
    return make_error(ErrorCode::invalid_argument,
                      "the root cannot be unmapped while other tiles are mapped");
  resident_.erase(it);
  const std::uint32_t fallback = t.z == 0 ? 0 : resolve_packed(ancestor_at(t, t.z - 1));
  for_each_window_descendant(t, [&](int z, std::uint32_t x, std::uint32_t y) {
    // Only cells that pointed at t itself change: the one level-t.z ancestor of a descendant is t.
    auto e = PageEntry::unpack(cell(z, x, y));
    if (e && e->level == t.z) write(z, x, y, fallback);
  });
  return {};
}

void ClipmapPageTable::recenter(int z, std::uint32_t cx, std::uint32_t cy) {
  if (!pyramid_.valid_level(z)) return;
  const auto clamp_origin = [&](std::uint32_t c, std::uint32_t tiles) -> std::uint32_t {
    if (tiles <= w_) return 0;
    const std::int64_t o = std::int64_t{c} - std::int64_t{w_ / 2};
    return static_cast<std::uint32_t>(std::clamp<std::int64_t>(o, 0, std::int64_t{tiles} - w_));
  };
  const std::uint32_t nx = clamp_origin(cx, pyramid_.tiles_x(z));
  const std::uint32_t ny = clamp_origin(cy, pyramid_.tiles_y(z));
  const std::uint32_t old_x = ox_[z], old_y = oy_[z];
  if (nx == old_x && ny == old_y) return;
  ox_[z] = nx;
  oy_[z] = ny;
  // At most the level's tile count, a uint32.
  const auto x1 =
      std::uint32_t(std::min<std::uint64_t>(std::uint64_t{nx} + w_, pyramid_.tiles_x(z)));
  const auto y1 =
      std::uint32_t(std::min<std::uint64_t>(std::uint64_t{ny} + w_, pyramid_.tiles_y(z)));
  for (std::uint32_t y = ny; y < y1; ++y) {
    const bool row_kept = y - old_y < w_;
    for (std::uint32_t x = nx; x < x1; ++x) {
      // A tile already in the old window already holds its correct value in its cell.
      if (row_kept && x - old_x < w_) continue;
      write(z, x, y, resolve_packed(TileId{static_cast<std::uint8_t>(z), x, y}));
    }
  }
}

std::vector<DirtySpan> ClipmapPageTable::take_dirty() {
  std::vector<DirtySpan> out;
  for (int z = 0; z < kMaxLevels; ++z) {
    if (!layer_dirty_[z]) continue;
    layer_dirty_[z] = 0;
    const std::size_t base = std::size_t(z) * w_ * w_;
    for (std::uint32_t row = 0; row < w_; ++row) {
      const std::size_t r = base + std::size_t(row) * w_;
      std::uint32_t x = 0;
      while (x < w_) {
        const auto changed = [&](std::uint32_t c) {
          return dirty_[r + c] && cells_[r + c] != shown_[r + c];
        };
        if (!changed(x)) {
          dirty_[r + x] = 0;
          ++x;
          continue;
        }
        const std::uint32_t start = x;
        while (x < w_ && changed(x)) {
          shown_[r + x] = cells_[r + x];
          dirty_[r + x] = 0;
          ++x;
        }
        out.push_back(DirtySpan{z, row, start, x});
      }
    }
  }
  return out;
}

}  // namespace vts::renderer
