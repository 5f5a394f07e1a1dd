// Saved source descriptions: a cache folder remembers what each upstream it was filled from is,
// so the tileset can be opened with the network gone (see saved_source.hpp).
#include "vts/client/saved_source.hpp"

#include <cstdio>
#include <ctime>
#include <nlohmann/json.hpp>
#include <system_error>

#include "vts/base/file_io.hpp"
#include "vts/protocol/json_input.hpp"

namespace vts::client {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// FNV-1a 64: a stable file name for an upstream location (not a security boundary: the file
// records the location it belongs to, which is checked on reading).
std::string location_hash(std::string_view location) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : location) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

// A URL's query may hold credentials (a signature, a token that rotates): it is neither written
// to the cache nor needed to find the description again.
std::string_view without_query(std::string_view location) {
  const bool url = location.starts_with("http://") || location.starts_with("https://");
  return url ? location.substr(0, location.find('?')) : location;
}

fs::path source_file(const fs::path& cache_dir, std::string_view location) {
  return cache_dir / "sources" / (location_hash(location) + ".json");
}

}  // namespace

// Atomic, so that another daemon or a crash never leaves a half-written file behind.
Status save_source_info(const fs::path& cache_dir, std::string_view location,
                        const SourceInfo& info) {
  location = without_query(location);
  const fs::path file = source_file(cache_dir, location);
  std::error_code ec;
  fs::create_directories(file.parent_path(), ec);
  if (ec)
    return make_error(ErrorCode::io,
                      "cannot create " + file.parent_path().string() + ": " + ec.message());
  json j = {
      {"vtstream_cache_source", 1},
      {"location", std::string(location)},
      {"key", info.key},
      {"version", info.version},
      {"metadata", json::parse(info.info.to_json(), nullptr, false)},
      {"description_json", info.description_json},
      {"image_format", info.image_format},
      {"image_tile_size", info.image_tile_size},
      {"min_zoom", info.min_zoom},
      {"saved_unix", std::int64_t(std::time(nullptr))},
  };
  const std::string text = j.dump(2, ' ', false, json::error_handler_t::replace) + "\n";
  return write_file_atomically(file, text);
}

Result<SourceInfo> load_source_info(const fs::path& cache_dir, std::string_view location) {
  location = without_query(location);
  const fs::path file = source_file(cache_dir, location);
  auto text = read_file(file);
  if (!text)
    return make_error(ErrorCode::not_found, "the cache in " + cache_dir.string() +
                                                " holds no description of " +
                                                std::string(location) + " (" + file.string() + ")");
  auto bad = [&](const std::string& why) {
    return make_error(ErrorCode::corrupt, file.string() + ": " + why);
  };
  // Depth-limited: the cache folder may be shared, or damaged.
  auto parsed = parse_json(*text, file.string());
  if (!parsed) return std::move(parsed).error();
  const json& j = *parsed;
  if (!j.is_object() || !j.contains("vtstream_cache_source")) return bad("not a saved source");
  try {
    if (j.at("location").get<std::string>() != location)
      return bad("describes another upstream (" + j.at("location").get<std::string>() + ")");
    SourceInfo info;
    info.key = j.at("key").get<std::string>();
    info.version = j.at("version").get<std::string>();
    info.description_json = j.at("description_json").get<std::string>();
    // Image tilesets (absent in files saved before them: our tiles).
    info.image_format = j.value("image_format", std::string());
    info.image_tile_size = j.value("image_tile_size", std::uint32_t{0});
    info.min_zoom = j.value("min_zoom", 0);
    auto meta = TilesetInfo::from_json(j.at("metadata").dump());
    if (!meta) return bad(meta.error().message);
    info.info = std::move(*meta);
    if (info.key.empty()) return bad("empty key");
    return info;
  } catch (const json::exception& e) {
    return bad(e.what());
  }
}

}  // namespace vts::client
