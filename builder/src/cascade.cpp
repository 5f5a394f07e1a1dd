#include "cascade.hpp"

#include <algorithm>
#include <cassert>
#include <cstring>

namespace vts {
inline namespace builder {
namespace detail {

namespace {

constexpr std::uint64_t kLanczosReach = 3;  // coarse texels a fine texel reaches beyond its parent

std::uint64_t floor_half_minus(std::uint64_t v, std::uint64_t pad) {
  return v / 2 > pad ? v / 2 - pad : 0;
}

}  // namespace

TexelRect coarser_window(const Geometry& g, int z, const TexelRect& w, DownsampleFilter filter) {
  const std::uint64_t pad = filter == DownsampleFilter::lanczos3 ? kLanczosReach : 0;
  return TexelRect{floor_half_minus(w.x0, pad), floor_half_minus(w.y0, pad),
                   std::min(g.level_width(z - 1), (w.x1 + 1) / 2 + pad),
                   std::min(g.level_height(z - 1), (w.y1 + 1) / 2 + pad)};
}

std::uint64_t stripe_halo(const Geometry& g, int levels, DownsampleFilter filter) {
  // A parent is exact when every child under its filter is: with an exact margin of d texels
  // around aligned columns, the parent level keeps floor(d / 2) (box) or floor((d - 5) / 2)
  // (lanczos3: children 2p - 5 ... 2p + 6). Work back from the coarsest level (margin 0: only
  // its own columns are kept) through levels whose tiles read B texels beyond their columns.
  std::uint64_t need = 0;
  for (int k = 1; k <= levels; ++k) {
    const std::uint64_t from_parent =
        filter == DownsampleFilter::lanczos3 ? 2 * need + 5 : 2 * need;
    need = std::max<std::uint64_t>(g.border(), from_parent);
  }
  return need;
}

struct Cascade::Level {
  TexelRect window;
  std::uint64_t cap = 0;                   // ring rows
  std::vector<std::uint8_t> ring;          // window row y lives in slot y % cap
  std::uint64_t end_row = 0;               // rows [window.y0, end_row) have been pushed
  TileRect emit;                           // tiles to cut
  std::uint32_t next_tile_row = 0;         // next tile row of `emit` to cut
  TexelRect parent;                        // level z - 1's window
  std::uint64_t pad_x = 0;                 // parent.x0 * 2 - window.x0 <= 0: zero texels before
  std::uint64_t padded_w = 0;              // child texels [2 parent.x0, 2 parent.x0 + padded_w)
  std::uint64_t next_parent_row = 0;       // box: next row of level z - 1 to make
  std::vector<std::uint8_t> pad_a, pad_b;  // child rows widened to the parent's alignment
  std::vector<std::uint8_t> parent_row;
  std::unique_ptr<LanczosReducer> reducer;  // lanczos3: makes level z - 1's rows instead
  std::uint64_t reducer_rows = 0;           // padded child rows pushed into the reducer
  std::vector<std::uint8_t> zero_row;       // padded_w transparent texels
};

Cascade::Cascade(const Geometry& g, int finest, int coarsest, std::vector<TexelRect> windows,
                 DownsampleFilter filter, std::vector<TileRect> emit, TileSink tiles, RowSink rows)
    : g_(g),
      finest_(finest),
      coarsest_(coarsest),
      tiles_(std::move(tiles)),
      rows_(std::move(rows)) {
  levels_.resize(static_cast<std::size_t>(finest) + 1);
  for (int z = coarsest; z <= finest; ++z) {
    auto l = std::make_unique<Level>();
    l->window = windows[static_cast<std::size_t>(z)];
    l->cap = g.stored_size() + 2;
    l->ring.resize(l->cap * l->window.width() * 4);
    l->end_row = l->window.y0;
    l->emit = emit[static_cast<std::size_t>(z)];
    l->next_tile_row = l->emit.y0;
    if (z > coarsest) {
      l->parent = windows[static_cast<std::size_t>(z - 1)];
      assert(l->parent == coarser_window(g, z, l->window, filter));
      l->pad_x = l->window.x0 - 2 * l->parent.x0;
      l->padded_w = std::min(2 * l->parent.x1, g.level_width(z)) - 2 * l->parent.x0;
      l->next_parent_row = l->parent.y0;
      l->parent_row.resize(l->parent.width() * 4);
      l->zero_row.assign(l->padded_w * 4, 0);
      const bool aligned = l->pad_x == 0 && l->padded_w == l->window.width();
      if (!aligned) {
        l->pad_a.assign(l->padded_w * 4, 0);
        l->pad_b.assign(l->padded_w * 4, 0);
      }
      if (filter == DownsampleFilter::lanczos3) {
        const std::uint64_t padded_h =
            std::min(2 * l->parent.y1, g.level_height(z)) - 2 * l->parent.y0;
        l->reducer = std::make_unique<LanczosReducer>(l->padded_w, padded_h);
      }
    }
    levels_[static_cast<std::size_t>(z)] = std::move(l);
  }
  // Tile rows wholly above the first window row (all transparent) and parent rows made only of
  // transparent children are ready before any row arrives.
  for (int z = finest; z >= coarsest; --z) emit_tile_rows(z);
}

Cascade::~Cascade() = default;

void Cascade::push_row(const std::uint8_t* row) {
  push_row(finest_, row);
}

const std::uint8_t* Cascade::row_at(int z, std::uint64_t y) const {
  const Level& l = *levels_[static_cast<std::size_t>(z)];
  if (y < l.window.y0 || y >= l.end_row) return nullptr;
  return l.ring.data() + (y % l.cap) * l.window.width() * 4;
}

std::uint64_t Cascade::oldest_needed(int z) const {
  const Level& l = *levels_[static_cast<std::size_t>(z)];
  const std::int64_t tile_start =
      std::int64_t{l.next_tile_row} * g_.tile_size() - std::int64_t{g_.border()};
  std::uint64_t oldest = static_cast<std::uint64_t>(std::max<std::int64_t>(tile_start, 0));
  if (l.emit.x0 >= l.emit.x1 || l.next_tile_row >= l.emit.y1) oldest = l.end_row;  // none to cut
  // The reducer keeps its own (filtered) copy of what it still needs.
  if (z > coarsest_ && !l.reducer) oldest = std::min(oldest, 2 * l.next_parent_row);
  return oldest;
}

void Cascade::push_row(int z, const std::uint8_t* row) {
  Level& l = *levels_[static_cast<std::size_t>(z)];
  assert(l.end_row < l.window.y1);
  assert(l.end_row < l.window.y0 + l.cap || l.end_row - l.cap < oldest_needed(z));
  std::memcpy(l.ring.data() + (l.end_row % l.cap) * l.window.width() * 4, row,
              l.window.width() * 4);
  ++l.end_row;
  if (z == coarsest_ && rows_) rows_(l.end_row - 1, row);
  emit_tile_rows(z);
  if (z > coarsest_) make_parent_rows(z);
}

void Cascade::emit_tile_rows(int z) {
  Level& l = *levels_[static_cast<std::size_t>(z)];
  if (l.emit.x0 >= l.emit.x1) return;
  const std::uint64_t T = g_.tile_size(), B = g_.border();
  while (l.next_tile_row < l.emit.y1) {
    // The last row the tile row reads (clamped to the image); rows past the window are
    // transparent and need not arrive.
    const std::uint64_t last =
        std::min({(l.next_tile_row + 1) * T + B, g_.level_height(z), l.window.y1});
    if (l.end_row < last) break;
    for (std::uint32_t tx = l.emit.x0; tx < l.emit.x1; ++tx) cut_tile(z, tx, l.next_tile_row);
    ++l.next_tile_row;
  }
}

void Cascade::cut_tile(int z, std::uint32_t tx, std::uint32_t ty) {
  const Level& l = *levels_[static_cast<std::size_t>(z)];
  const std::uint32_t S = g_.stored_size();
  const TileId id{static_cast<std::uint8_t>(z), tx, ty};
  TileImage img;
  img.width = img.height = S;
  img.pixels.assign(std::size_t{S} * S * 4, 0);
  const std::int64_t w = static_cast<std::int64_t>(g_.level_width(z));
  const std::int64_t x_start = std::int64_t{tx} * g_.tile_size() - g_.border();
  const auto wx0 = static_cast<std::int64_t>(l.window.x0);
  const auto wx1 = static_cast<std::int64_t>(l.window.x1);
  // Columns clamp to the image; image columns outside the window stay transparent. In stored
  // columns: [0, left) repeat image column 0, [left, right) are x_start + sx, [right, S) repeat
  // column w - 1.
  const auto left = static_cast<std::uint32_t>(std::clamp<std::int64_t>(-x_start, 0, S));
  const auto right = static_cast<std::uint32_t>(std::clamp<std::int64_t>(w - x_start, left, S));
  const auto copy0 =
      static_cast<std::uint32_t>(std::clamp<std::int64_t>(wx0 - x_start, left, right));
  const auto copy1 =
      static_cast<std::uint32_t>(std::clamp<std::int64_t>(wx1 - x_start, copy0, right));
  for (std::uint32_t sy = 0; sy < S; ++sy) {
    const std::uint8_t* src = row_at(z, g_.stored_to_level_y(id, sy));
    if (!src) continue;
    std::uint8_t* dst = img.pixels.data() + std::size_t{sy} * S * 4;
    if (left > 0 && wx0 == 0)
      for (std::uint32_t sx = 0; sx < left; ++sx) std::memcpy(dst + 4 * sx, src, 4);
    if (copy1 > copy0)
      std::memcpy(dst + 4 * copy0, src + 4 * (x_start + copy0 - wx0),
                  std::size_t{copy1 - copy0} * 4);
    if (right < S && wx1 == w) {
      const std::uint8_t* last = src + 4 * (w - 1 - wx0);
      for (std::uint32_t sx = right; sx < S; ++sx) std::memcpy(dst + 4 * sx, last, 4);
    }
  }
  tiles_(id, std::move(img));
}

void Cascade::make_parent_rows(int z) {
  Level& l = *levels_[static_cast<std::size_t>(z)];
  const std::uint64_t h = g_.level_height(z);
  const std::uint64_t y0 = 2 * l.parent.y0, y1 = std::min(2 * l.parent.y1, h);
  // A child row widened to [2 parent.x0, 2 parent.x0 + padded_w), transparent outside the window.
  auto widened = [&](std::uint64_t y, std::vector<std::uint8_t>& buf) -> const std::uint8_t* {
    const std::uint8_t* src = row_at(z, y);
    if (!src) return l.zero_row.data();
    if (buf.empty()) return src;  // the window is already the parent's alignment
    std::memcpy(buf.data() + l.pad_x * 4, src, l.window.width() * 4);
    return buf.data();
  };
  if (l.reducer) {
    // Padded rows: transparent ones above the window, the window's, transparent ones below it.
    while (l.reducer_rows < y1 - y0) {
      const std::uint64_t y = y0 + l.reducer_rows;
      if (y >= l.window.y0 && y < l.window.y1 && y >= l.end_row) break;  // not pushed yet
      if (y >= l.window.y1 && l.end_row < l.window.y1) break;  // below: after the window's end
      l.reducer->push_row(widened(y, l.pad_a));
      ++l.reducer_rows;
      while (l.reducer->ready()) {
        l.reducer->pop_row(l.parent_row.data());
        push_row(z - 1, l.parent_row.data());
      }
    }
    return;
  }
  while (l.next_parent_row < l.parent.y1) {
    const std::uint64_t r0 = 2 * l.next_parent_row, r1 = std::min(r0 + 1, h - 1);
    // Ready once its lower child has arrived or lies past the window (transparent).
    if (std::min(r1, l.window.y1 - 1) >= l.end_row) break;
    const std::uint8_t* a = widened(r0, l.pad_a);
    const std::uint8_t* b = widened(r1, l.pad_b);
    downsample_row_rgba8(a, b, l.padded_w, l.parent_row.data(), l.parent.width());
    ++l.next_parent_row;
    push_row(z - 1, l.parent_row.data());
  }
}

}  // namespace detail
}  // namespace builder
}  // namespace vts
