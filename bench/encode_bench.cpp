// The web-image encoder's benchmark driver (for bench/encode_bench.sh): the content of a sample of
// an archive's tiles (every k-th existing tile whose content is opaque, spread over all levels, as
// `vts serve` would crop it for /{z}/{x}/{y}.png|.webp) encoded in this process with each setting
// asked for, one thread. Per setting it prints one JSON line: bytes per tile, encode time per tile
// (this thread's CPU time, the best of --passes passes over the sample: time per core), and the
// quality: PNG decoded back and compared texel for texel ("exact"), WebP's PSNR of RGB against
// the source content (one mean squared error over every sampled texel).
//
// With --raw-dir DIR it also writes the sample for the peer (vips) as raw 8-bit RGB strips,
// DIR/strip_NNN.raw, each --strip tiles stacked vertically (256 x 256*strip texels), and
// DIR/strips.txt ("FILE WIDTH HEIGHT" per line).
//
//   vts_encode_bench ARCHIVE [--tiles N] [--passes N] [--raw-dir DIR] [--strip N] SETTING...
//
// SETTING: png[:level=L][,filter=F] or webp[:quality=Q][,method=M] (WebEncodeOptions' fields; F
// the number of a PngFilter: 0 none, 1 sub, 2 up, 3 average, 4 paeth, 5 adaptive).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "vts/archive/inspect.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/imaging/web_image.hpp"

namespace {

using vts::TileId;
using vts::TileImage;
using vts::imaging::WebEncodeOptions;
using vts::imaging::WebFormat;

int fail(const std::string& message) {
  std::fprintf(stderr, "vts_encode_bench: %s\n", message.c_str());
  return 1;
}

double thread_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

struct Setting {
  std::string name;
  WebFormat format = WebFormat::png;
  WebEncodeOptions options;
};

// "png:level=1,filter=up" -> Setting; false on an unknown key or format.
bool parse_setting(const std::string& text, Setting& s) {
  s.name = text;
  const std::size_t colon = text.find(':');
  const std::string format = text.substr(0, colon);
  if (format == "png") {
    s.format = WebFormat::png;
  } else if (format == "webp") {
    s.format = WebFormat::webp;
  } else {
    return false;
  }
  std::string rest = colon == std::string::npos ? "" : text.substr(colon + 1);
  while (!rest.empty()) {
    const std::size_t comma = rest.find(',');
    const std::string kv = rest.substr(0, comma);
    rest = comma == std::string::npos ? "" : rest.substr(comma + 1);
    const std::size_t eq = kv.find('=');
    if (eq == std::string::npos) return false;
    const std::string key = kv.substr(0, eq);
    const int value = std::stoi(kv.substr(eq + 1));
    if (key == "level") {
      s.options.png_level = value;
    } else if (key == "filter") {
      if (value < 0 || value > int(vts::imaging::PngFilter::adaptive)) return false;
      s.options.png_filter = vts::imaging::PngFilter(value);
    } else if (key == "quality") {
      s.options.webp_quality = value;
    } else if (key == "method") {
      s.options.webp_method = value;
    } else {
      return false;
    }
  }
  return bool(vts::imaging::validate(s.options));
}

bool opaque(const TileImage& t) {
  for (std::size_t i = 3; i < t.pixels.size(); i += 4)
    if (t.pixels[i] != 255) return false;
  return true;
}

// Every k-th existing tile (tile-id order, so all levels) whose content is opaque, up to `count`.
vts::Result<std::vector<TileImage>> sample(const std::string& path, std::size_t count) {
  auto reader = vts::archive::Reader::open(path);
  if (!reader) return reader.error();
  auto info = vts::archive::archive_tileset((*reader)->header(), (*reader)->metadata_json());
  if (!info) return info.error();
  std::vector<std::uint64_t> ids;
  auto listed = (*reader)->for_each_entry([&ids](const vts::archive::Entry& e) {
    for (std::uint32_t i = 0; i < e.run_length; ++i) ids.push_back(e.tile_id + i);
    return true;
  });
  if (!listed) return listed.error();
  std::vector<TileImage> out;
  const std::size_t step = std::max<std::size_t>(1, ids.size() / std::max<std::size_t>(1, count));
  for (std::size_t i = 0; i < ids.size() && out.size() < count; i += step) {
    auto id = vts::archive::tile_id_to_zxy(ids[i]);
    if (!id) return id.error();
    auto stored = vts::archive::read_tile_rgba8(**reader, *info, *id);
    if (!stored) return stored.error();
    auto content = vts::imaging::tile_content(*stored, info->geometry, *id);
    if (!content) return content.error();
    if (opaque(*content)) out.push_back(std::move(*content));
  }
  return out;
}

// The strips of the sample for vips (RGB, `per_strip` tiles stacked vertically).
bool write_strips(const std::vector<TileImage>& tiles, const std::filesystem::path& dir,
                  std::size_t per_strip) {
  std::filesystem::create_directories(dir);
  std::ofstream list(dir / "strips.txt");
  for (std::size_t first = 0, n = 0; first < tiles.size(); first += per_strip, ++n) {
    char name[32];
    std::snprintf(name, sizeof name, "strip_%03zu.raw", n);
    std::ofstream out(dir / name, std::ios::binary);
    const std::size_t last = std::min(tiles.size(), first + per_strip);
    for (std::size_t i = first; i < last; ++i) {
      const auto& p = tiles[i].pixels;
      for (std::size_t j = 0; j < p.size(); j += 4)
        out.write(reinterpret_cast<const char*>(&p[j]), 3);
    }
    list << name << " " << tiles[first].width << " " << (last - first) * tiles[first].height
         << "\n";
    if (!out) return false;
  }
  return bool(list);
}

// Encodes every tile with `s`; prints the JSON line. False when an encode or decode fails.
bool run(const Setting& s, const std::vector<TileImage>& tiles, int passes) {
  std::vector<std::vector<std::uint8_t>> encoded(tiles.size());
  double best = 1e30;
  for (int p = 0; p < passes; ++p) {
    const double t0 = thread_seconds();
    for (std::size_t i = 0; i < tiles.size(); ++i) {
      auto e = vts::imaging::encode_web_image(tiles[i], s.format, s.options);
      if (!e) return fail(s.name + ": " + e.error().to_string()) == 0;
      encoded[i] = std::move(*e);
    }
    best = std::min(best, thread_seconds() - t0);
  }
  double bytes = 0, squared = 0, samples = 0;
  bool exact = true;
  for (std::size_t i = 0; i < tiles.size(); ++i) {
    bytes += double(encoded[i].size());
    auto back = vts::imaging::decode_web_image(encoded[i]);
    if (!back) return fail(s.name + ": " + back.error().to_string()) == 0;
    exact = exact && back->pixels == tiles[i].pixels;
    for (std::size_t j = 0; j < back->pixels.size(); ++j) {
      if (j % 4 == 3) continue;
      const double d = double(back->pixels[j]) - double(tiles[i].pixels[j]);
      squared += d * d;
      samples += 1;
    }
  }
  const double n = double(tiles.size());
  const double psnr = squared == 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 * samples / squared);
  std::printf(
      "{\"setting\": \"%s\", \"tiles\": %zu, \"bytes_per_tile\": %.0f, \"ms_per_tile\": %.3f, "
      "\"psnr_db\": %.2f, \"exact\": %s}\n",
      s.name.c_str(), tiles.size(), bytes / n, best / n * 1e3, psnr, exact ? "true" : "false");
  std::fflush(stdout);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::string archive, raw_dir;
  std::size_t count = 256, per_strip = 32;
  int passes = 3;
  std::vector<Setting> settings;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--tiles" && i + 1 < argc) {
      count = std::stoul(argv[++i]);
    } else if (a == "--passes" && i + 1 < argc) {
      passes = std::max(1, std::stoi(argv[++i]));
    } else if (a == "--raw-dir" && i + 1 < argc) {
      raw_dir = argv[++i];
    } else if (a == "--strip" && i + 1 < argc) {
      per_strip = std::max<std::size_t>(1, std::stoul(argv[++i]));
    } else if (archive.empty()) {
      archive = a;
    } else {
      Setting s;
      if (!parse_setting(a, s)) return fail("bad setting '" + a + "'");
      settings.push_back(s);
    }
  }
  if (archive.empty()) return fail("usage: vts_encode_bench ARCHIVE [options] SETTING...");
  auto tiles = sample(archive, count);
  if (!tiles) return fail(tiles.error().to_string());
  if (tiles->empty()) return fail("no opaque tile in " + archive);
  if (!raw_dir.empty() && !write_strips(*tiles, raw_dir, per_strip))
    return fail("cannot write the strips in " + raw_dir);
  for (const Setting& s : settings)
    if (!run(s, *tiles, passes)) return 1;
  return 0;
}
