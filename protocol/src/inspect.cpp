#include "vts/protocol/inspect.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <unordered_set>

namespace vts {

Result<ArchiveSummary> summarize_archive(const pmtiles::Reader& reader) {
  ArchiveSummary s;
  auto info = TilesetInfo::from_json(reader.metadata_json());
  if (!info) return std::move(info).error();
  s.info = std::move(info).value();
  s.header = reader.header();
  s.file_bytes = reader.size();
  const Geometry& g = s.info.geometry;
  for (int z = 0; z <= g.max_zoom(); ++z)
    s.levels.push_back({z, g.level_width(z), g.level_height(z), g.tile_count(z), 0, 0});
  std::unordered_set<std::uint64_t> seen_offsets;
  Status walk = reader.for_each_entry([&](const pmtiles::Entry& e) {
    ++s.entries;
    if (seen_offsets.insert(e.offset).second) ++s.unique_tiles;
    for (std::uint32_t i = 0; i < e.run_length; ++i) {
      auto id = pmtiles::tile_id_to_zxy(e.tile_id + i);
      ++s.addressed_tiles;
      s.addressed_bytes += e.length;
      if (id && id->z <= g.max_zoom()) {
        auto& l = s.levels[id->z];
        ++l.tiles_present;
        l.bytes += e.length;
      }
    }
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
    const pmtiles::Reader& reader, unsigned threads,
    const std::function<void(std::uint64_t, std::uint64_t)>& on_progress) {
  VerifyReport report;
  auto info = TilesetInfo::from_json(reader.metadata_json());
  if (!info) return std::move(info).error();
  const Geometry& g = info->geometry;
  if (reader.header().max_zoom != g.max_zoom())
    report.structural_error = "header max_zoom " + std::to_string(reader.header().max_zoom) +
                              " differs from the metadata's " + std::to_string(g.max_zoom());

  // Distinct payloads, each with the first tile id that uses it; plus every tile outside the
  // pyramid. Decoding each payload once keeps verification proportional to the stored bytes.
  struct Payload {
    std::uint64_t offset, length, first_tile_id, uses;
  };
  std::vector<Payload> payloads;
  std::unordered_map<std::uint64_t, std::size_t> by_offset;
  std::uint64_t first_bad_id = UINT64_MAX;
  auto note_bad = [&](std::uint64_t tile_id, std::uint64_t count, const std::string& why) {
    report.bad_tiles += count;
    if (tile_id < first_bad_id) {
      first_bad_id = tile_id;
      report.first_error = why;
    }
  };
  Status walk = reader.for_each_entry([&](const pmtiles::Entry& e) {
    report.tiles_checked += e.run_length;
    for (std::uint32_t i = 0; i < e.run_length; ++i) {
      auto id = pmtiles::tile_id_to_zxy(e.tile_id + i);
      if (!id || !g.exists(*id)) {
        note_bad(e.tile_id + i, 1,
                 "tile id " + std::to_string(e.tile_id + i) + " lies outside the pyramid");
      }
    }
    auto [it, inserted] = by_offset.emplace(e.offset, payloads.size());
    if (inserted)
      payloads.push_back({e.offset, e.length, e.tile_id, e.run_length});
    else
      payloads[it->second].uses += e.run_length;
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
      } else {
        // Size, codec and pixel format against the tileset (before the decode allocates).
        auto img = decode_tile(*bytes, info->tile_spec());
        if (!img) err = img.error();
      }
      if (err) {
        std::lock_guard lock(m);
        // Every tile sharing a bad payload is bad; name the first of them.
        note_bad(p.first_tile_id, p.uses, err->to_string());
      }
      ++done;
    }
  };
  const unsigned n = threads ? threads : std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < n; ++t) pool.emplace_back(worker);
  if (on_progress) {
    std::thread progress_worker(worker);
    while (done < payloads.size()) {
      on_progress(done, payloads.size());
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    progress_worker.join();
    on_progress(done, payloads.size());
  } else {
    worker();
  }
  for (auto& t : pool) t.join();
  report.payloads_checked = payloads.size();
  if (first_bad_id != UINT64_MAX) {
    auto id = pmtiles::tile_id_to_zxy(first_bad_id);
    if (id) report.first_bad = *id;
  }
  return report;
}

}  // namespace vts
