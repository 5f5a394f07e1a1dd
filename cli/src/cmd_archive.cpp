// vts info / verify: inspect an archive: ours, or a stock raster PMTiles (PNG/JPEG/WebP tiles
// without our metadata, such as `vts export` writes), described and checked as the client reads it.
#include <cstdio>
#include <nlohmann/json.hpp>
#include <optional>

#include "commands.hpp"
#include "progress.hpp"
#include "stock_archive.hpp"
#include "vts/archive/inspect.hpp"
#include "vts/base/file_io.hpp"
#include "vts/client/image_tiles.hpp"

namespace vts::cli {

namespace {

void print_info_json(const std::string& path, const archive::ArchiveSummary& s) {
  const Geometry& g = s.info.geometry;
  nlohmann::json j;
  j["path"] = path;
  j["name"] = s.info.name;
  j["description"] = s.info.description;
  j["format_version"] = s.info.format_version;
  j["width"] = g.width();
  j["height"] = g.height();
  j["tile_size"] = g.tile_size();
  j["border"] = g.border();
  j["stored_size"] = g.stored_size();
  j["max_zoom"] = g.max_zoom();
  j["codec"] = codec_name(s.info.codec);
  j["color_space"] = s.info.color_space;
  j["downsample"] = s.info.downsample;
  j["sparse"] = s.info.sparse;
  j["content_hash"] = s.info.content_hash;
  if (const auto& geo = s.info.georeference) {
    const LonLatBounds& b = geo->bounds;
    j["georeference"] = {{"tiling", std::string(tiling_name(geo->tiling))},
                         {"crs", geo->crs()},
                         {"bounds", {b.west, b.south, b.east, b.north}},
                         {"center", {geo->center.lon, geo->center.lat, geo->center.level}},
                         {"tiles_present", s.addressed_tiles},
                         {"tiles_full_grid", g.total_tile_count()}};
  }
  j["tiles"] = s.addressed_tiles;
  j["unique_tiles"] = s.unique_tiles;
  j["entries"] = s.entries;
  j["leaf_directories"] = s.leaf_directories;
  j["bytes"] = s.file_bytes;
  j["tile_bytes"] = s.stored_bytes;
  j["addressed_bytes"] = s.addressed_bytes;
  j["dedup_ratio"] = s.dedup_ratio;
  j["bytes_per_tile"] = s.addressed_tiles ? double(s.addressed_bytes) / s.addressed_tiles : 0.0;
  j["levels"] = nlohmann::json::array();
  for (const auto& l : s.levels)
    j["levels"].push_back({{"z", l.z},
                           {"width", l.width},
                           {"height", l.height},
                           {"tiles", l.tiles_present},
                           {"tiles_possible", l.tiles_possible},
                           {"bytes", l.bytes}});
  std::printf("%s\n", j.dump(2).c_str());
}

void print_info_text(const std::string& path, const archive::ArchiveSummary& s) {
  const Geometry& g = s.info.geometry;
  std::printf("%s\n", path.c_str());
  std::printf("  name         %s\n", s.info.name.c_str());
  std::printf("  image        %llu x %llu texels, %s, downsampled %s\n",
              (unsigned long long)g.width(), (unsigned long long)g.height(),
              s.info.color_space.c_str(), s.info.downsample.c_str());
  std::printf("  tiles        %u + 2x%u border = %u texels stored, levels 0..%d%s\n", g.tile_size(),
              g.border(), g.stored_size(), g.max_zoom(), s.info.sparse ? " (sparse)" : "");
  std::printf("  codec        %s (format v%d)\n", codec_name(s.info.codec), s.info.format_version);
  if (const auto& geo = s.info.georeference) {
    const LonLatBounds& b = geo->bounds;
    std::printf("  georef       %s (%s), bounds %.9g,%.9g,%.9g,%.9g, center %.9g,%.9g level %d\n",
                std::string(tiling_name(geo->tiling)).c_str(), geo->crs().c_str(), b.west, b.south,
                b.east, b.north, geo->center.lon, geo->center.lat, geo->center.level);
    std::printf("  coverage     %llu of the full grid's %llu tiles (%.4g%%)\n",
                (unsigned long long)s.addressed_tiles, (unsigned long long)g.total_tile_count(),
                100.0 * double(s.addressed_tiles) / double(g.total_tile_count()));
  }
  std::printf("  archive      %s, %llu tiles, %llu unique, %llu entries, %llu leaf directories\n",
              human_bytes(s.file_bytes).c_str(), (unsigned long long)s.addressed_tiles,
              (unsigned long long)s.unique_tiles, (unsigned long long)s.entries,
              (unsigned long long)s.leaf_directories);
  std::printf("  dedup        %.3fx (%s addressed, %s stored), %.1f KiB/tile\n", s.dedup_ratio,
              human_bytes(s.addressed_bytes).c_str(), human_bytes(s.stored_bytes).c_str(),
              s.addressed_tiles ? double(s.addressed_bytes) / s.addressed_tiles / 1024.0 : 0.0);
  std::printf("  %5s %12s %12s %10s %12s\n", "level", "width", "height", "tiles", "bytes");
  for (const auto& l : s.levels)
    std::printf("  %5d %12llu %12llu %10llu %12s\n", l.z, (unsigned long long)l.width,
                (unsigned long long)l.height, (unsigned long long)l.tiles_present,
                human_bytes(l.bytes).c_str());
}

int run_info(const std::string& path, bool json) {
  auto reader = open_archive(path);
  if (!reader) return report_error(reader.error());
  if (auto stock = stock_archive(**reader, path)) {
    if (!*stock) return report_error(stock->error());
    auto summary = archive::summarize_archive(**reader, (*stock)->info);
    if (!summary) {
      Error e = summary.error();
      e.message = "'" + path + "': " + e.message;
      return report_error(e);
    }
    print_stock_info(path, **stock, *summary, json);
    return 0;
  }
  auto summary = archive::summarize_archive(**reader);
  if (!summary) {
    Error e = summary.error();
    e.message = "'" + path + "': " + e.message;
    return report_error(e);
  }
  if (json)
    print_info_json(path, *summary);
  else
    print_info_text(path, *summary);
  return 0;
}

int run_verify(const std::string& path, bool json, unsigned threads) {
  auto reader = open_archive(path);
  if (!reader) return report_error(reader.error());
  auto stock = stock_archive(**reader, path);
  if (stock && !*stock) return report_error(stock->error());
  ProgressBar bar("verify", "payloads", !json);
  const auto progress = [&](std::uint64_t done, std::uint64_t total) { bar.update(done, total); };
  Result<archive::VerifyReport> report = archive::VerifyReport{};
  if (stock) {
    // Every tile must decode as the image type the header declares, at the tile size: what the
    // client's decoders accept (client::decode_image_tile).
    const client::SourceInfo& si = **stock;
    const archive::PayloadCheck decodes = [&si](std::span<const std::uint8_t> payload) -> Status {
      auto img = client::decode_image_tile(payload, si.image_format, si.image_tile_size);
      if (!img) return img.error();
      return {};
    };
    report = archive::verify_archive(**reader, si.info, decodes, threads, progress);
  } else {
    report = archive::verify_archive(**reader, threads, progress);
  }
  bar.finish();
  if (!report) {
    Error e = report.error();
    e.message = "'" + path + "': " + e.message;
    return report_error(e);
  }
  const archive::VerifyReport& r = *report;
  if (json) {
    nlohmann::json j{{"path", path},
                     {"kind", stock ? "stock-raster" : "vtstream"},
                     {"ok", r.ok()},
                     {"tiles_checked", r.tiles_checked},
                     {"payloads_checked", r.payloads_checked},
                     {"bad_tiles", r.bad_tiles}};
    if (r.first_bad) j["first_bad_tile"] = r.first_bad->to_string();
    if (!r.first_error.empty()) j["first_error"] = r.first_error;
    if (!r.structural_error.empty()) j["structural_error"] = r.structural_error;
    std::printf("%s\n", j.dump(2).c_str());
  }
  if (!r.structural_error.empty()) {
    std::fprintf(stderr, "vts: error: '%s': %s\n", path.c_str(), r.structural_error.c_str());
    return exit_code(ErrorCode::corrupt);
  }
  if (r.bad_tiles) {
    std::fprintf(stderr, "vts: error: '%s': %llu of %llu tiles are bad; first bad tile %s: %s\n",
                 path.c_str(), (unsigned long long)r.bad_tiles, (unsigned long long)r.tiles_checked,
                 r.first_bad ? r.first_bad->to_string().c_str() : "?", r.first_error.c_str());
    return exit_code(ErrorCode::corrupt);
  }
  if (!json && stock)
    std::printf("%s: ok, %llu tiles (%llu distinct payloads) decode as %u px %s images; %s\n",
                path.c_str(), (unsigned long long)r.tiles_checked,
                (unsigned long long)r.payloads_checked, (*stock)->image_tile_size,
                (*stock)->image_format.c_str(), stock_kind(**stock).c_str());
  else if (!json)
    std::printf("%s: ok, %llu tiles (%llu distinct payloads) verified\n", path.c_str(),
                (unsigned long long)r.tiles_checked, (unsigned long long)r.payloads_checked);
  return 0;
}

}  // namespace

Runner add_info(CLI::App& app) {
  auto path = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  CLI::App* c = app.add_subcommand(
      "info",
      "Describe an archive (ours or a stock raster PMTiles): geometry, tiles per level, bytes");
  c->add_option("archive", *path, "Archive (.pmtiles)")->required();
  c->add_flag("--json", *json, "Print as JSON");
  return [path, json] { return run_info(*path, *json); };
}

Runner add_verify(CLI::App& app) {
  auto path = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  auto threads = std::make_shared<unsigned>(0);
  CLI::App* c = app.add_subcommand("verify",
                                   "Check every directory and decode every tile (checksums; a "
                                   "stock raster archive's images); exit 0 only if all good");
  c->add_option("archive", *path, "Archive (.pmtiles)")->required();
  c->add_option("--threads", *threads, "Decoder threads (0 = all cores)")
      ->check(CLI::Range(0u, kMaxThreads));
  c->add_flag("--json", *json, "Print the report as JSON");
  return [path, json, threads] { return run_verify(*path, *json, *threads); };
}

}  // namespace vts::cli
