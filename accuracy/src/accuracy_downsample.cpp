// Table: downsample (accuracy/include/vts/accuracy/accuracy.hpp). For each of the builder's
// downsampling filters (BuildOptions::downsample): the pyramid of ctx.input is built with it and
// every level below the finest is read back from the archive and compared with a high-quality
// resize of the full-resolution source straight to that level's size (OpenImageIO
// ImageBufAlgo::resize, in linear light, premultiplied alpha) — with two reference filters,
// Lanczos-3 and Blackman-Harris, so that no filter is judged only by a reference of its own kind —
// next to the build's time, rate and bytes.
#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <new>
#include <string>
#include <system_error>
#include <vector>

#include "vts/accuracy/accuracy.hpp"
#include "vts/archive/pmtiles.hpp"
#include "vts/builder/builder.hpp"
#include "vts/builder/downsample.hpp"
#include "vts/protocol/codec.hpp"
#include "vts/protocol/tileset.hpp"

namespace vts::accuracy {

namespace {

namespace fs = std::filesystem;
namespace OIIO = OIIO_NAMESPACE;

constexpr const char* kReferenceFilters[] = {"lanczos3", "blackman-harris"};
constexpr int kReferences = 2;

struct Rgba {
  std::uint64_t w = 0, h = 0;
  std::vector<std::uint8_t> px;
};

// Level z of an archive, stitched from its tiles' contents.
Result<Rgba> read_level(const archive::Reader& reader, const Geometry& g, int z,
                        std::uint64_t* payload_bytes) {
  Rgba out{g.level_width(z), g.level_height(z), {}};
  out.px.resize(out.w * out.h * 4);
  const std::uint32_t S = g.stored_size(), B = g.border();
  *payload_bytes = 0;
  for (std::uint32_t ty = 0; ty < g.tiles_y(z); ++ty)
    for (std::uint32_t tx = 0; tx < g.tiles_x(z); ++tx) {
      const TileId id{static_cast<std::uint8_t>(z), tx, ty};
      auto bytes = reader.get(id);
      if (!bytes) return std::move(bytes).error();
      *payload_bytes += bytes->size();
      auto tile = decode_tile(*bytes);
      if (!tile) return std::move(tile).error();
      if (tile->format != PixelFormat::rgba8 || tile->width != S || tile->height != S)
        return make_error(ErrorCode::corrupt, "tile " + id.to_string() + " is not " +
                                                  std::to_string(S) + "x" + std::to_string(S) +
                                                  " rgba8");
      const TexelRect r = g.content_rect(id);
      for (std::uint64_t y = r.y0; y < r.y1; ++y)
        std::memcpy(&out.px[(y * out.w + r.x0) * 4], &tile->pixels[((B + y - r.y0) * S + B) * 4],
                    r.width() * 4);
    }
  return out;
}

// The finest level as linear, premultiplied float RGBA: what the references are made from.
std::vector<float> to_linear_premultiplied(const Rgba& img) {
  std::vector<float> f(img.px.size());
  for (std::size_t i = 0; i < img.px.size(); i += 4) {
    const float a = img.px[i + 3] / 255.0f;
    for (int c = 0; c < 3; ++c) f[i + c] = decode_srgb8(img.px[i + c]) * a;
    f[i + 3] = a;
  }
  return f;
}

// The reference for a level `steps` reductions below the finest (w x h texels there): level texel
// i covers finest texels [i 2^steps, (i + 1) 2^steps), so the source is first extended by edge
// replication (the pyramid's clamp-to-edge convention) to w 2^steps x h 2^steps, then resized
// in one step by OpenImageIO with `filter`.
Result<Rgba> reference_level(const Rgba& finest, const std::vector<float>& linear, int steps,
                             std::uint64_t w, std::uint64_t h, const char* filter) {
  const std::uint64_t pw = w << steps, ph = h << steps;
  OIIO::ImageBuf src(OIIO::ImageSpec(int(pw), int(ph), 4, OIIO::TypeDesc::FLOAT));
  if (pw == finest.w && ph == finest.h) {
    src.set_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, linear.data());
  } else {
    std::vector<float> padded(pw * ph * 4);
    for (std::uint64_t y = 0; y < ph; ++y) {
      const std::uint64_t sy = std::min(y, finest.h - 1);
      for (std::uint64_t x = 0; x < pw; ++x) {
        const std::uint64_t sx = std::min(x, finest.w - 1);
        std::memcpy(&padded[(y * pw + x) * 4], &linear[(sy * finest.w + sx) * 4], 16);
      }
    }
    src.set_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, padded.data());
  }
  OIIO::ImageBuf dst(OIIO::ImageSpec(int(w), int(h), 4, OIIO::TypeDesc::FLOAT));
  if (!OIIO::ImageBufAlgo::resize(dst, src, filter))
    return make_error(ErrorCode::internal,
                      std::string("OpenImageIO resize (") + filter + ") failed: " + dst.geterror());
  std::vector<float> r(w * h * 4);
  if (!dst.get_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, r.data()))
    return make_error(ErrorCode::internal, "OpenImageIO get_pixels failed: " + dst.geterror());
  Rgba out{w, h, std::vector<std::uint8_t>(w * h * 4)};
  for (std::size_t i = 0; i < r.size(); i += 4) {
    const float a = r[i + 3];
    for (int c = 0; c < 3; ++c) out.px[i + c] = a > 1e-6f ? encode_srgb8(r[i + c] / a) : 0;
    out.px[i + 3] = static_cast<std::uint8_t>(std::lround(std::clamp(a, 0.0f, 1.0f) * 255));
  }
  return out;
}

struct Diff {
  double sum_sq = 0;  // over R, G, B codes
  std::uint64_t samples = 0;
  int max_error = 0;
  double psnr() const {
    if (samples == 0) return kNotMeasured;
    if (sum_sq == 0) return std::numeric_limits<double>::infinity();
    return 10 * std::log10(255.0 * 255.0 / (sum_sq / double(samples)));
  }
};

// Colour error in 8-bit sRGB codes. Alpha is not scored (the test images are opaque and a
// reference's alpha is exact wherever the source's is constant).
Diff compare(const Rgba& a, const Rgba& b) {
  Diff d;
  for (std::size_t i = 0; i < a.px.size(); i += 4)
    for (int c = 0; c < 3; ++c) {
      const int e = std::abs(int(a.px[i + c]) - int(b.px[i + c]));
      d.sum_sq += double(e) * e;
      d.max_error = std::max(d.max_error, e);
      ++d.samples;
    }
  return d;
}

using Clock = std::chrono::steady_clock;

std::string size_text(std::uint64_t w, std::uint64_t h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

// ctx.quick: the input reduced to at most 512 texels wide, written to the work directory, so the
// table keeps its shape at a fraction of the cost.
Result<fs::path> quick_input(const AccuracyContext& ctx) {
  OIIO::ImageBuf in(ctx.input.string());
  if (!in.read(0, 0, true, OIIO::TypeDesc::UINT8))
    return make_error(ErrorCode::io, "cannot read " + ctx.input.string() + ": " + in.geterror());
  const int w = in.spec().width, h = in.spec().height;
  if (w <= 512) return ctx.input;
  const int qw = 512, qh = std::max(1, int(std::lround(double(h) * qw / w)));
  OIIO::ImageBuf small(OIIO::ImageSpec(qw, qh, in.spec().nchannels, OIIO::TypeDesc::UINT8));
  if (!OIIO::ImageBufAlgo::resize(small, in, "lanczos3"))
    return make_error(ErrorCode::internal, "cannot reduce the quick input: " + small.geterror());
  const fs::path out = ctx.work_dir / "downsample_quick_input.png";
  if (!small.write(out.string()))
    return make_error(ErrorCode::io, "cannot write " + out.string() + ": " + small.geterror());
  return out;
}

Result<AccuracyTable> measure_downsampling(const AccuracyContext& ctx) {
  std::error_code ec;
  if (!fs::is_regular_file(ctx.input, ec))
    return make_error(ErrorCode::not_found, "input image " + ctx.input.string() + " not found");
  if (!fs::is_directory(ctx.work_dir, ec))
    return make_error(ErrorCode::not_found,
                      "work directory " + ctx.work_dir.string() + " does not exist");
  fs::path input = ctx.input;
  if (ctx.quick) {
    auto q = quick_input(ctx);
    if (!q) return std::move(q).error();
    input = *q;
  }
  // Timed builds use the configuration the project ships (tile 256, border 4; quick: 64) and keep
  // the fastest of a few runs. The levels are compared on a second build with 32-texel tiles,
  // which reaches down to a 32-texel level: a level's texels do not depend on the tile size (the
  // cascade's output is tested equal to whole-image reductions), only how many levels exist does.
  const std::uint32_t timed_tile = ctx.quick ? 64 : 256, level_tile = 32;
  const int timed_runs = ctx.quick ? 1 : 3;

  AccuracyTable t;
  t.id = "downsample";
  t.title =
      "Downsampling filter in the builder: PSNR of every level against a high-quality "
      "resize of the source, and the build time it costs";
  t.columns = {{"filter", "filter", 0},
               {"level", "level", 0},
               {"size", "size (texels)", 0},
               {"psnr_lanczos3_db", "PSNR vs Lanczos-3 ref (dB)", 2},
               {"max_error_lanczos3", "max err vs Lanczos-3 (codes)", 0},
               {"psnr_blackman_harris_db", "PSNR vs Blackman-Harris ref (dB)", 2},
               {"max_error_blackman_harris", "max err vs Blackman-Harris (codes)", 0},
               {"level_bytes", "level tile bytes", 0},
               {"reduce_ns_per_texel", "reduce (ns/texel)", 2},
               {"build_s", "build (s)", 3},
               {"tiles_per_s", "tiles/s", 0},
               {"archive_bytes", "archive bytes", 0}};
  TablePlot plots[kReferences];
  for (int r = 0; r < kReferences; ++r) {
    plots[r].id = std::string("downsample_psnr_") + kReferenceFilters[r];
    plots[r].title = std::string("Pyramid level PSNR against a direct ") + kReferenceFilters[r] +
                     " resize of the source";
    plots[r].x_label = "levels below the finest (reduction 2^n)";
    plots[r].y_label = "PSNR (dB)";
  }

  const DownsampleFilter filters[] = {DownsampleFilter::box, DownsampleFilter::lanczos3};
  Rgba finest;                // the source as the builder sees it (RGBA8), from the first archive
  std::vector<float> linear;  // finest, linear premultiplied
  std::vector<Rgba> references[kReferences];  // [ref][steps - 1]
  double build_seconds[2] = {0, 0};
  for (std::size_t fi = 0; fi < std::size(filters); ++fi) {
    const DownsampleFilter f = filters[fi];
    const std::string name = downsample_filter_name(f);
    BuildOptions o;
    o.inputs = {input};
    o.border = 4;
    o.downsample = f;
    o.name = "downsample-" + name;
    double best = std::numeric_limits<double>::infinity();
    BuildReport timed;
    for (int run = 0; run < timed_runs; ++run) {
      ctx.say("downsample: building with " + name + " (" + std::to_string(run + 1) + "/" +
              std::to_string(timed_runs) + ")");
      o.tile_size = timed_tile;
      o.output = ctx.work_dir / ("downsample_" + name + "_timed.pmtiles");
      auto report = build_pyramid(o);
      if (!report) return std::move(report).error();
      if (report->seconds < best) {
        best = report->seconds;
        timed = *report;
      }
      fs::remove(o.output, ec);
    }
    build_seconds[fi] = best;

    o.tile_size = level_tile;
    o.output = ctx.work_dir / ("downsample_" + name + "_levels.pmtiles");
    auto built = build_pyramid(o);
    if (!built) return std::move(built).error();
    auto reader = archive::Reader::open(o.output);
    if (!reader) return std::move(reader).error();
    const Geometry& g = built->info.geometry;
    const int maxz = g.max_zoom();
    std::uint64_t bytes = 0;
    if (finest.px.empty()) {
      auto lv = read_level(**reader, g, maxz, &bytes);
      if (!lv) return std::move(lv).error();
      finest = std::move(*lv);
      linear = to_linear_premultiplied(finest);
    }
    // The filter alone: one reduction of the finest level on this thread, per finest texel (the
    // cascade's share of a build; it runs on the building thread next to the encoder pool).
    double reduce_ns = std::numeric_limits<double>::infinity();
    for (int run = 0; run < timed_runs; ++run) {
      const auto t0 = Clock::now();
      const auto reduced = downsample_image_rgba8(finest.px.data(), finest.w, finest.h, f);
      const double s = std::chrono::duration<double>(Clock::now() - t0).count();
      if (reduced.empty()) break;
      reduce_ns = std::min(reduce_ns, s * 1e9 / double(finest.w * finest.h));
    }
    for (auto& p : plots) p.series.push_back(PlotSeries{name, {}});
    std::uint64_t level_bytes_sum = 0;
    double mse_sum[kReferences] = {0, 0};
    int worst[kReferences] = {0, 0};
    int compared = 0;
    for (int z = maxz - 1; z >= 0; --z) {
      const int steps = maxz - z;
      ctx.say("downsample: " + name + " level " + std::to_string(z) + " (" +
              size_text(g.level_width(z), g.level_height(z)) + ")");
      auto level = read_level(**reader, g, z, &bytes);
      if (!level) return std::move(level).error();
      std::vector<Cell> row = {name, double(z), size_text(level->w, level->h)};
      for (int r = 0; r < kReferences; ++r) {
        auto& refs = references[r];
        if (refs.size() < std::size_t(steps)) {
          auto ref =
              reference_level(finest, linear, steps, level->w, level->h, kReferenceFilters[r]);
          if (!ref) return std::move(ref).error();
          refs.push_back(std::move(*ref));
        }
        const Diff d = compare(*level, refs[std::size_t(steps - 1)]);
        row.push_back(d.psnr());
        row.push_back(double(d.max_error));
        mse_sum[r] += d.samples ? d.sum_sq / double(d.samples) : 0;
        worst[r] = std::max(worst[r], d.max_error);
        if (std::isfinite(d.psnr())) plots[r].series.back().points.push_back({steps, d.psnr()});
      }
      row.push_back(double(bytes));
      level_bytes_sum += bytes;
      row.push_back(kNotMeasured);
      row.push_back(kNotMeasured);
      row.push_back(kNotMeasured);
      row.push_back(kNotMeasured);
      t.rows.push_back(std::move(row));
      ++compared;
    }
    fs::remove(o.output, ec);
    std::vector<Cell> all = {name, std::string("all levels"), std::string("")};
    for (int r = 0; r < kReferences; ++r) {
      // PSNR of the levels' mean squared error, each level weighted alike (a plain mean of dB
      // would be infinite as soon as one level is exact).
      const double mse = compared ? mse_sum[r] / compared : kNotMeasured;
      all.push_back(mse > 0    ? 10 * std::log10(255.0 * 255.0 / mse)
                    : mse == 0 ? std::numeric_limits<double>::infinity()
                               : kNotMeasured);
      all.push_back(compared ? double(worst[r]) : kNotMeasured);
    }
    all.push_back(double(level_bytes_sum));
    all.push_back(reduce_ns);
    all.push_back(best);
    all.push_back(best > 0 ? double(timed.stats.addressed_tiles) / best : kNotMeasured);
    all.push_back(double(timed.stats.file_bytes));
    t.rows.push_back(std::move(all));
  }
  for (auto& p : plots) t.plots.push_back(std::move(p));
  if (finest.w <= level_tile && finest.h <= level_tile)
    t.notes.push_back("the input fits in one " + std::to_string(level_tile) +
                      "-texel tile: there is no coarser level to compare");

  t.notes.push_back("input: " + input.filename().string() + " " + size_text(finest.w, finest.h) +
                    (ctx.quick ? " (quick: the input reduced to 512 texels wide)" : ""));
  t.notes.push_back(
      "every level below the finest is read back from the archive (lossless tiles) and compared "
      "in 8-bit sRGB codes (R, G, B) with OpenImageIO's ImageBufAlgo::resize of the "
      "full-resolution "
      "source straight to that level's size, done in linear light on premultiplied alpha; the "
      "source is first extended by edge replication to a whole number of level texels, as the "
      "pyramid's clamp-to-edge convention has it");
  t.notes.push_back(
      "two reference filters: Lanczos-3 (the same family as the builder's lanczos3, but one "
      "direct resize instead of a cascade of 2x steps) and Blackman-Harris (a different, softer "
      "windowed kernel), so that neither filter is only judged against a copy of itself");
  t.notes.push_back(
      "'all levels' rows: PSNR of the levels' mean squared error (every level weighted alike), "
      "the worst level's max error, the listed levels' tile bytes; reduce: one reduction of the "
      "finest level by the filter alone on one thread, per finest texel (the building thread's "
      "share; a pyramid reduces 4/3 of the finest texel count); the timed build's seconds, tiles "
      "per second and file bytes");
  t.notes.push_back(
      "reading the PSNR columns: the Lanczos-3 reference keeps detail up to each level's Nyquist "
      "frequency, the Blackman-Harris one (radius 1.5 level texels) is soft; the filter whose "
      "response is nearer the reference's scores higher, so a sharp filter leads against the "
      "first and the blurring box against the second. Max error is largest at hard edges, where "
      "Lanczos-3 rings (clamped to [0, 1])");
  t.notes.push_back("build: vts build defaults (lossless, zstd 3, tile " +
                    std::to_string(timed_tile) + ", border 4, all cores), fastest of " +
                    std::to_string(timed_runs) +
                    " runs, decoding the input included; levels compared on a build with " +
                    std::to_string(level_tile) +
                    "-texel tiles (same texels, more levels). The finest level is the source "
                    "itself (lossless) and is not listed");
  if (build_seconds[0] > 0)
    t.notes.push_back("build time lanczos3 / box: " + [&] {
      char b[32];
      std::snprintf(b, sizeof b, "%.2f", build_seconds[1] / build_seconds[0]);
      return std::string(b);
    }());
  return t;
}

}  // namespace

Result<AccuracyTable> downsample_table(const AccuracyContext& ctx) {
  try {
    return measure_downsampling(ctx);
  } catch (const std::bad_alloc&) {
    return make_error(ErrorCode::too_large,
                      "downsample table: out of memory for " + ctx.input.string());
  } catch (const std::exception& e) {
    return make_error(ErrorCode::internal, std::string("downsample table: ") + e.what());
  }
}

}  // namespace vts::accuracy
