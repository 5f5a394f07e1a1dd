// `vts info` and `vts verify` over an archive.
//
// Both walk every directory entry once and never iterate over the tile ids of a run: an entry
// may address 2^32 - 1 tiles (one hostile entry of a few bytes), so a run is split at level
// boundaries and counted with arithmetic on the Hilbert quadtree (Pyramid below), and each
// distinct payload is decoded once however many tiles share it.
#include "vts/archive/inspect.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstring>
#include <map>
#include <mutex>
#include <new>
#include <optional>
#include <set>
#include <system_error>
#include <thread>
#include <utility>

namespace vts::archive {
namespace {

constexpr int kMaxTileZ = 31;  // the deepest level a tile id can name

// The pieces of the tile-id run [first, first + count) that lie on one level each: calls
// piece(z, lo, hi) in id order with lo..hi inside level z; ids beyond level 31 (no tile has them)
// come as z = kMaxTileZ + 1.
template <typename Piece>
void split_by_level(std::uint64_t first, std::uint64_t count, Piece&& piece) {
  if (count == 0) return;
  const std::uint64_t last = first + (count - 1);  // no overflow: the walk checked first + count
  std::uint64_t lo = first;
  for (int z = 0; z <= kMaxTileZ; ++z) {
    const archive::TileIdRange level = archive::subtree_tile_ids(TileId{}, std::uint8_t(z));
    if (lo > level.last) continue;
    const std::uint64_t hi = std::min(last, level.last);
    piece(z, lo, hi);
    if (hi == last) return;
    lo = hi + 1;
  }
  piece(kMaxTileZ + 1, lo, last);
}

// Which tile ids of a level the geometry holds: its tiles are the rectangle x < tiles_x(z),
// y < tiles_y(z). Both questions walk the Hilbert quadtree from 0/0/0 and descend only into the
// squares an id range cuts (at most two per depth) or that straddle the rectangle's edge, so
// they cost O(z) lookups whatever the range's length.
class Pyramid {
 public:
  explicit Pyramid(const Geometry& g) : g_(g) {}

  // Ids in [lo, hi] (level z) of tiles that exist.
  std::uint64_t count_inside(int z, std::uint64_t lo, std::uint64_t hi) const {
    if (!g_.valid_level(z)) return 0;
    return count(TileId{}, z, lo, hi);
  }

  // The first id in [lo, hi] (level z) of a tile that does not exist; nullopt when all do.
  std::optional<std::uint64_t> first_outside(int z, std::uint64_t lo, std::uint64_t hi) const {
    if (!g_.valid_level(z)) return lo;
    return first_out(TileId{}, z, lo, hi);
  }

 private:
  // How many tiles of node's square at level z lie in the rectangle.
  std::uint64_t overlap(TileId node, int z) const {
    const unsigned shift = unsigned(z - node.z);
    const std::uint64_t side = std::uint64_t{1} << shift;
    const std::uint64_t x0 = std::uint64_t{node.x} << shift, y0 = std::uint64_t{node.y} << shift;
    const std::uint64_t w = g_.tiles_x(z), h = g_.tiles_y(z);
    if (x0 >= w || y0 >= h) return 0;
    return (std::min(w, x0 + side) - x0) * (std::min(h, y0 + side) - y0);
  }

  static std::array<TileId, 4> children(TileId t) {
    const auto z = std::uint8_t(t.z + 1);
    return {TileId{z, 2 * t.x, 2 * t.y}, TileId{z, 2 * t.x + 1, 2 * t.y},
            TileId{z, 2 * t.x, 2 * t.y + 1}, TileId{z, 2 * t.x + 1, 2 * t.y + 1}};
  }

  std::uint64_t count(TileId node, int z, std::uint64_t lo, std::uint64_t hi) const {
    const archive::TileIdRange r = archive::subtree_tile_ids(node, std::uint8_t(z));
    if (r.last < lo || r.first > hi) return 0;
    const std::uint64_t in_rect = overlap(node, z);
    if (in_rect == 0 || (lo <= r.first && r.last <= hi)) return in_rect;
    std::uint64_t n = 0;
    for (TileId c : children(node)) n += count(c, z, lo, hi);
    return n;
  }

  std::optional<std::uint64_t> first_out(TileId node, int z, std::uint64_t lo,
                                         std::uint64_t hi) const {
    const archive::TileIdRange r = archive::subtree_tile_ids(node, std::uint8_t(z));
    if (r.last < lo || r.first > hi) return std::nullopt;
    const std::uint64_t in_rect = overlap(node, z);
    if (in_rect == r.last - r.first + 1) return std::nullopt;  // wholly inside the rectangle
    if (in_rect == 0) return std::max(r.first, lo);            // wholly outside
    std::array<TileId, 4> cs = children(node);
    std::sort(cs.begin(), cs.end(), [z](TileId a, TileId b) {
      return archive::subtree_tile_ids(a, std::uint8_t(z)).first <
             archive::subtree_tile_ids(b, std::uint8_t(z)).first;
    });
    for (TileId c : cs) {
      if (auto id = first_out(c, z, lo, hi)) return id;
    }
    return std::nullopt;
  }

  const Geometry& g_;
};

Error thread_error(unsigned started, unsigned wanted, const std::system_error& e) {
  return make_error(ErrorCode::io, "cannot start decoder thread " + std::to_string(started + 1) +
                                       " of " + std::to_string(wanted) + ": " + e.what() +
                                       " (lower --threads or the process limits)");
}

}  // namespace

Result<TilesetInfo> archive_tileset(const archive::Header& header,
                                    const std::string& metadata_json) {
  Result<TilesetInfo> info = TilesetInfo::from_json(metadata_json);
  if (!info) return info;
  if (header.tile_compression != archive::Compression::zstd) {
    return make_error(ErrorCode::corrupt,
                      "header field tile_compression is " +
                          std::to_string(int(header.tile_compression)) +
                          ", but a vtstream archive's tiles are zstd streams (4)");
  }
  return info;
}

Result<ArchiveSummary> summarize_archive(const archive::Reader& reader) {
  auto info = archive_tileset(reader.header(), reader.metadata_json());
  if (!info) return std::move(info).error();
  return summarize_archive(reader, *info);
}

Result<ArchiveSummary> summarize_archive(const archive::Reader& reader, const TilesetInfo& info) {
  ArchiveSummary s;
  s.info = info;
  s.header = reader.header();
  s.file_bytes = reader.size();
  const Geometry& g = s.info.geometry;
  for (int z = 0; z <= g.max_zoom(); ++z)
    s.levels.push_back({z, g.level_width(z), g.level_height(z), g.tile_count(z), 0, 0});
  std::set<std::pair<std::uint64_t, std::uint32_t>> payloads;  // (offset, length)
  Status walk = reader.for_each_entry([&](const archive::Entry& e) {
    ++s.entries;
    if (payloads.emplace(e.offset, e.length).second) ++s.unique_tiles;
    s.addressed_tiles += e.run_length;
    s.addressed_bytes += std::uint64_t{e.run_length} * e.length;
    split_by_level(e.tile_id, e.run_length, [&](int z, std::uint64_t lo, std::uint64_t hi) {
      if (!g.valid_level(z)) return;
      LevelSummary& l = s.levels[std::size_t(z)];
      l.tiles_present += hi - lo + 1;
      l.bytes += (hi - lo + 1) * e.length;
    });
    return true;
  });
  if (!walk) return walk.error();
  auto leaves = reader.leaf_directory_count();
  if (!leaves) return std::move(leaves).error();
  s.leaf_directories = *leaves;
  s.stored_bytes = s.header.tile_data_length;
  s.dedup_ratio = s.stored_bytes ? double(s.addressed_bytes) / double(s.stored_bytes) : 1.0;
  return s;
}

Result<VerifyReport> verify_archive(
    const archive::Reader& reader, unsigned threads,
    const std::function<void(std::uint64_t, std::uint64_t)>& on_progress) {
  auto info = archive_tileset(reader.header(), reader.metadata_json());
  if (!info) return std::move(info).error();
  const TileSpec spec = info->tile_spec();
  // Size, codec and pixel format against the tileset (before the decode allocates).
  const PayloadCheck decodes = [&spec](std::span<const std::uint8_t> payload) -> Status {
    auto img = decode_tile(payload, spec);
    if (!img) return img.error();
    return {};
  };
  return verify_archive(reader, *info, decodes, threads, on_progress);
}

Result<VerifyReport> verify_archive(
    const archive::Reader& reader, const TilesetInfo& info, const PayloadCheck& check,
    unsigned threads, const std::function<void(std::uint64_t, std::uint64_t)>& on_progress) {
  VerifyReport report;
  const Geometry& g = info.geometry;
  const Pyramid pyramid(g);
  if (reader.header().max_zoom != g.max_zoom())
    report.structural_error = "header max_zoom " + std::to_string(reader.header().max_zoom) +
                              " differs from the metadata's " + std::to_string(g.max_zoom());

  // Distinct payloads (by offset and length), each with the first tile id that uses it and the
  // number of its tiles inside the pyramid: a tile outside is bad whatever its payload, and is
  // counted once. Decoding each payload once keeps verification proportional to the stored bytes.
  struct Payload {
    std::uint64_t first_tile_id = 0, uses_inside = 0;
  };
  std::vector<Payload> payloads;
  std::map<std::pair<std::uint64_t, std::uint32_t>, std::size_t> by_offset;
  std::uint64_t first_bad_id = UINT64_MAX;
  auto note_bad = [&](std::uint64_t tile_id, std::uint64_t count, const std::string& why) {
    report.bad_tiles += count;
    if (tile_id < first_bad_id) {
      first_bad_id = tile_id;
      report.first_error = why;
    }
  };
  Status walk = reader.for_each_entry([&](const archive::Entry& e) {
    report.tiles_checked += e.run_length;
    std::uint64_t inside = 0;
    split_by_level(e.tile_id, e.run_length, [&](int z, std::uint64_t lo, std::uint64_t hi) {
      const std::uint64_t in = pyramid.count_inside(z, lo, hi);
      inside += in;
      if (in == hi - lo + 1) return;
      // Look for the first outside tile only where it could come before the first bad so far.
      const std::uint64_t out =
          lo < first_bad_id ? pyramid.first_outside(z, lo, hi).value_or(lo) : lo;
      note_bad(out, hi - lo + 1 - in,
               "tile id " + std::to_string(out) + " lies outside the pyramid");
    });
    auto [it, inserted] = by_offset.emplace(std::pair(e.offset, e.length), payloads.size());
    if (inserted) payloads.push_back({e.tile_id, 0});
    payloads[it->second].uses_inside += inside;
    return true;
  });
  if (!walk) {
    report.structural_error = walk.error().to_string();
    return report;
  }

  std::atomic<std::size_t> next{0};
  std::atomic<std::uint64_t> done{0};
  std::mutex m;
  auto worker = [&] {
    for (;;) {
      const std::size_t i = next++;
      if (i >= payloads.size()) return;
      const Payload& p = payloads[i];
      auto bytes = reader.get_by_tile_id(p.first_tile_id);
      std::optional<Error> err;
      if (!bytes) {
        err = bytes.error();
      } else if (Status s = check(*bytes); !s) {
        err = s.error();
      }
      if (err) {
        std::lock_guard lock(m);
        // Every tile inside the pyramid sharing a bad payload is bad; name the first of them.
        note_bad(p.first_tile_id, p.uses_inside, err->to_string());
      }
      ++done;
    }
  };
  // The pool: n workers, the calling thread one of them unless it reports progress. A thread
  // that cannot start (a tasks or address-space limit) stops the others after their current
  // payload; every thread started is joined before the error is returned.
  const unsigned n = threads ? threads : std::max(1u, std::thread::hardware_concurrency());
  const unsigned helpers = on_progress ? n : n - 1;
  std::vector<std::thread> pool;
  std::optional<Error> start_failed;
  try {
    pool.reserve(helpers);
    for (unsigned t = 0; t < helpers; ++t) pool.emplace_back(worker);
  } catch (const std::system_error& e) {
    start_failed = thread_error(unsigned(pool.size()), helpers, e);
  } catch (const std::bad_alloc&) {
    start_failed = make_error(
        ErrorCode::io, "out of memory starting " + std::to_string(helpers) + " decoder threads");
  }
  if (start_failed) {
    next = payloads.size();
    for (auto& t : pool) t.join();
    return *start_failed;
  }
  if (on_progress) {
    while (done < payloads.size()) {
      on_progress(done, payloads.size());
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    on_progress(done, payloads.size());
  } else {
    worker();
  }
  for (auto& t : pool) t.join();
  report.payloads_checked = payloads.size();
  if (first_bad_id != UINT64_MAX) {
    auto id = archive::tile_id_to_zxy(first_bad_id);
    if (id) report.first_bad = *id;
  }
  return report;
}

Result<TileImage> read_tile_rgba8(const archive::Reader& reader, const TilesetInfo& info,
                                  TileId id) {
  auto bytes = reader.get(id);
  if (!bytes) {
    Error e = std::move(bytes).error();
    if (e.message.find(id.to_string()) == std::string::npos)
      e.message = "tile " + id.to_string() + ": " + e.message;
    return e;
  }
  // The tileset's TileSpec refuses a tile of another size or codec before anything is decoded.
  auto img = decode_tile(*bytes, info.tile_spec());
  if (img && img->format == PixelFormat::bc1) img = bc1_to_rgba8(*img);
  if (!img) {
    Error e = std::move(img).error();
    e.message = "tile " + id.to_string() + ": " + e.message;
    return e;
  }
  return img;
}

TileImage extracted_texels(const TileImage& stored, const Geometry& geometry, TileId id,
                           bool with_border) {
  if (with_border) return stored;
  const std::uint32_t s = geometry.stored_size(), b = geometry.border();
  const TexelRect r = geometry.content_rect(id);
  TileImage out;
  out.width = static_cast<std::uint32_t>(r.width());
  out.height = static_cast<std::uint32_t>(r.height());
  out.pixels.resize(std::size_t{out.width} * out.height * 4);
  for (std::uint32_t y = 0; y < out.height; ++y)
    std::memcpy(&out.pixels[std::size_t{y} * out.width * 4],
                &stored.pixels[(std::size_t{b + y} * s + b) * 4], std::size_t{out.width} * 4);
  return out;
}

}  // namespace vts::archive
