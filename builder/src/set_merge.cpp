// A sharded build's output as a set of archives (vts/builder/shard.hpp, "Sets"): each archive a
// ranged merge of the same parts, the manifest written once all are there, and the join back
// into one archive.
#include <algorithm>
#include <set>

#include "shard_internal.hpp"
#include "vts/archive/archive_set.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/shard.hpp"

namespace vts {
inline namespace builder {
namespace {

namespace fs = std::filesystem;

std::uint64_t tile_order(TileId t) {
  return archive::zxy_to_tile_id(t.z, t.x, t.y);
}

fs::path empty_marker(const fs::path& out_dir, const std::string& name) {
  return out_dir / (name + ".empty");
}

// The archive's share of the tileset's bounds: its root tile's extent, clipped to them.
LonLatBounds clipped(const LonLatBounds& all, const LonLatBounds& tile) {
  return {std::max(all.west, tile.west), std::max(all.south, tile.south),
          std::min(all.east, tile.east), std::min(all.north, tile.north)};
}

// Whether `a` is `b` or one of its ancestors.
bool covers(TileId a, TileId b) {
  return a.z <= b.z && (b.x >> (b.z - a.z)) == a.x && (b.y >> (b.z - a.z)) == a.y;
}

// Which of the merge's parts (the apex first when the plan has one, then the shards in order, as
// merge_plan lists them) hold tiles of the archive of `root`: a shard's part holds its
// sub-pyramid's levels from the apex level down, the apex part the levels above it. The others
// are read for their manifests only (MergeOptions::index_needed).
std::vector<bool> parts_needed(const ShardPlan& plan, const std::optional<TileId>& root) {
  const int k = plan.archive_level, a = plan.apex_level;
  std::vector<bool> needed;
  if (a > 0) needed.push_back(!root || a > k);  // levels < a: the top's, and k..a-1 of each
  for (const TileId& s : plan.shards)
    needed.push_back(root ? covers(s, *root) || covers(*root, s) : a < k);
  return needed;
}

// What merge_set_archive() changes in the one-file merge: the tiles, zooms and header bounds,
// and which parts' indexes it reads.
void scope_to(const ShardPlan& plan, const std::optional<TileId>& root, archive::MergeOptions& mo) {
  const int k = plan.archive_level;
  mo.index_needed = parts_needed(plan, root);
  if (mo.index_needed.size() != mo.parts.size()) mo.index_needed.clear();  // read them all
  if (!root) {
    mo.ranges = {archive::levels_above(static_cast<std::uint8_t>(k))};
    mo.archive.min_zoom = 0;
    mo.archive.max_zoom = static_cast<std::uint8_t>(k - 1);
    return;
  }
  mo.ranges = archive::subtree_ranges(*root, static_cast<std::uint8_t>(plan.max_zoom));
  mo.archive.min_zoom = static_cast<std::uint8_t>(k);
  if (plan.geo) {
    const Georeference& geo = plan.geo->georeference;
    const LonLatBounds b =
        clipped(geo.bounds, tile_bounds_degrees(geo.tiling, plan.options.tile_size, *root));
    if (b.west < b.east && b.south < b.north) {
      const LonLatLevel center{(b.west + b.east) / 2, (b.south + b.north) / 2, k};
      mo.archive.bounds = archive::georeferenced_bounds(b, center);
    }
  }
}

}  // namespace

std::vector<std::optional<TileId>> set_archive_roots(const ShardPlan& plan) {
  const int k = plan.archive_level;
  if (k < 1 || k > plan.max_zoom) return {};
  auto g = detail::plan_geometry(plan);
  if (!g) return {};
  const TileRect level = detail::plan_emit_rects(plan, *g)[static_cast<std::size_t>(k)];
  std::set<std::uint64_t> keys;
  for (const TileId& s : plan.shards) {
    if (s.z >= k) {  // one archive holds the whole shard
      const int up = s.z - k;
      keys.insert(tile_key(TileId{static_cast<std::uint8_t>(k), s.x >> up, s.y >> up}));
      continue;
    }
    // The shard spans several archives: those of its level-k tiles the image covers.
    const TileRect r = detail::shard_rect(level, s, k);
    for (std::uint32_t y = r.y0; y < r.y1; ++y)
      for (std::uint32_t x = r.x0; x < r.x1; ++x)
        keys.insert(tile_key(TileId{static_cast<std::uint8_t>(k), x, y}));
  }
  std::vector<TileId> roots;
  for (std::uint64_t key : keys) {
    const TileId t = tile_from_key(key);
    if (t.x >= level.x0 && t.x < level.x1 && t.y >= level.y0 && t.y < level.y1) roots.push_back(t);
  }
  std::sort(roots.begin(), roots.end(),
            [](const TileId& a, const TileId& b) { return tile_order(a) < tile_order(b); });
  std::vector<std::optional<TileId>> out{std::nullopt};
  out.insert(out.end(), roots.begin(), roots.end());
  return out;
}

Result<SetArchiveReport> merge_set_archive(
    const ShardPlan& plan, const fs::path& parts_dir, const fs::path& out_dir, std::size_t index,
    const std::function<void(const archive::MergeProgress&)>& progress,
    const std::atomic<bool>* cancel, bool verify) {
  if (plan.archive_level < 1)
    return make_error(ErrorCode::invalid_argument,
                      "the plan makes one archive, not a set (vts plan --archive-level K)");
  const std::vector<std::optional<TileId>> roots = set_archive_roots(plan);
  if (index >= roots.size())
    return make_error(ErrorCode::invalid_argument, "--archive " + std::to_string(index) +
                                                       " is outside the set's archives 0.." +
                                                       std::to_string(roots.size() - 1));
  SetArchiveReport r;
  r.index = index;
  r.root = roots[index];
  r.name = archive::set_archive_name(r.root);
  const fs::path marker = empty_marker(out_dir, r.name);
  std::error_code ec;
  fs::remove(marker, ec);
  fs::path folder = out_dir;
  if (!folder.has_filename()) folder = folder.parent_path();  // "sets/planet/"
  auto merged = detail::merge_plan_scoped(
      plan, parts_dir, out_dir / r.name, folder,
      [&](archive::MergeOptions& mo) { scope_to(plan, r.root, mo); }, progress, cancel, verify);
  if (!merged && merged.error().code == ErrorCode::not_found &&
      merged.error().message == archive::kNoTileInRanges) {
    // No tile of the parts in this archive: remember that it was merged, empty.
    if (Status st = write_file_atomically(marker, ""); !st) return st.error();
    r.empty = true;
    return r;
  }
  if (!merged) return std::move(merged).error();
  r.merge = std::move(*merged);
  return r;
}

Result<archive::SetManifest> write_set_manifest(const ShardPlan& plan, const fs::path& out_dir) {
  const std::vector<std::optional<TileId>> roots = set_archive_roots(plan);
  if (roots.empty())
    return make_error(ErrorCode::invalid_argument,
                      "the plan makes one archive, not a set (vts plan --archive-level K)");
  archive::SetManifest m;
  m.archive_level = plan.archive_level;
  m.max_zoom = static_cast<std::uint8_t>(plan.max_zoom);
  std::vector<fs::path> markers;
  for (std::size_t i = 0; i < roots.size(); ++i) {
    const std::string name = archive::set_archive_name(roots[i]);
    std::error_code ec;
    if (fs::exists(empty_marker(out_dir, name), ec)) {
      markers.push_back(empty_marker(out_dir, name));
      continue;
    }
    auto reader = archive::Reader::open(out_dir / name);
    if (!reader) {
      if (reader.error().code != ErrorCode::not_found) return std::move(reader).error();
      return make_error(ErrorCode::not_found, (out_dir / name).string() +
                                                  " has not been merged yet (vts merge --plan " +
                                                  "... --archive " + std::to_string(i) + ")");
    }
    if (m.metadata_json.empty()) {
      m.metadata_json = (*reader)->metadata_json();
    } else if ((*reader)->metadata_json() != m.metadata_json) {
      return make_error(ErrorCode::invalid_argument,
                        (out_dir / name).string() +
                            " belongs to another build than the set's other archives (its "
                            "metadata differs): merge it again from this plan's parts");
    }
    m.archives.push_back({name, roots[i], (*reader)->size(), (*reader)->version()});
  }
  if (m.archives.empty() || m.archives.front().root)
    return make_error(ErrorCode::not_found, "the set has no top archive in " + out_dir.string());
  if (Status st = write_file_atomically(out_dir / archive::kSetManifestName, m.to_json()); !st)
    return st.error();
  for (const fs::path& marker : markers) {
    std::error_code ec;
    fs::remove(marker, ec);
  }
  return m;
}

Result<archive::WriterStats> join_set(const fs::path& set, const fs::path& output,
                                      const std::function<void(const JoinProgress&)>& progress,
                                      const std::atomic<bool>* cancel) {
  auto reader = archive::open_set_path(set);
  if (!reader) return std::move(reader).error();
  const archive::Reader& r = **reader;
  archive::WriterOptions wo;
  wo.path = output;
  const archive::Header& h = r.header();
  wo.internal_compression = h.internal_compression;
  wo.tile_compression = h.tile_compression;
  wo.tile_type = h.tile_type;
  wo.min_zoom = h.min_zoom;
  wo.max_zoom = h.max_zoom;
  wo.bounds = h;
  auto writer = archive::Writer::create(wo);
  if (!writer) return std::move(writer).error();
  JoinProgress p;
  p.tiles_total = h.addressed_tiles;
  std::vector<std::uint8_t> payload;
  Status inner;
  Status walked = r.for_each_entry([&](const archive::Entry& e) {
    payload.resize(e.length);
    if (inner = r.read(e.offset, payload); !inner) return false;
    for (std::uint32_t i = 0; i < e.run_length; ++i) {
      Result<TileId> id = archive::tile_id_to_zxy(e.tile_id + i);
      if (!id) {
        inner = id.error();
        return false;
      }
      if (inner = (*writer)->add_tile(*id, payload); !inner) return false;
      ++p.tiles_done;
    }
    if (progress) progress(p);
    return !(cancel && cancel->load());
  });
  if (!walked) return walked.error();
  if (!inner) return inner.error();
  if (cancel && cancel->load()) return make_error(ErrorCode::cancelled, "join cancelled");
  return (*writer)->finish(r.metadata_json());
}

}  // namespace builder
}  // namespace vts
