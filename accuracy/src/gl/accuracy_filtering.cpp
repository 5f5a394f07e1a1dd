// Table: filtering (accuracy/include/vts/accuracy/accuracy.hpp). Bilinear, trilinear and
// anisotropic 2/4/8 filtering of the virtual texture, each judged against a 16-sample supersampled
// reference of the same view (renderer/reference.hpp), and timed on the GPU (llvmpipe here).
#include <epoxy/gl.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "accuracy_views_common.hpp"
#include "vts/accuracy/accuracy.hpp"
#include "vts/renderer/reference.hpp"

namespace vts::accuracy {

namespace {

using namespace vts::renderer;
using views::Clock;

constexpr int kSuperFactor = 4;  // 4 x 4 = 16 samples per pixel
// The oblique view is also judged against 8 x 8 = 64 samples per pixel: a 16-sample truth takes
// 4 samples along the footprint's long axis, as 4 anisotropic taps do, so it cannot rank more
// taps than that (and flatters exactly 4).
constexpr int kFineFactor = 8;

struct Mode {
  const char* name;
  bool trilinear;
  int anisotropy;
};
constexpr Mode kModes[] = {{"bilinear", false, 1},
                           {"trilinear", true, 1},
                           {"anisotropic 2", true, 2},
                           {"anisotropic 4", true, 4},
                           {"anisotropic 8", true, 8}};
constexpr int kModeCount = 5;
constexpr int kTrilinear = 1;

Error filtering_fail(const Error& e, const std::string& what) {
  return Error{e.code, "filtering table: " + what + ": " + e.message};
}

// The views, fixed for an image: the first plane view straight down between two levels, the
// designated oblique view (the 'oblique' column) a plane tilted 1.2 rad, the globe seen
// obliquely; the full run adds a turned plane, a grazing plane and the globe from afar.
std::vector<views::View> filtering_views(const Geometry& g, int height, bool quick) {
  const double W = double(g.width()), H = double(g.height());
  std::vector<views::View> out;
  out.push_back(
      {"plane straight (1.7 texel/px)",
       std::make_shared<PlaneScene>(PlaneView{
           .center_u = 0.41 * W + 0.3, .center_v = 0.47 * H + 0.7, .texels_per_pixel = 1.7}),
       false});
  out.push_back({"plane oblique (tilt 1.2)",
                 std::make_shared<PlaneScene>(PlaneView{.center_u = 0.52 * W,
                                                        .center_v = 0.56 * H,
                                                        .texels_per_pixel = 0.9,
                                                        .heading = 0.3,
                                                        .tilt = 1.2}),
                 true});
  GlobeView globe;
  globe.lon_deg = 12;
  globe.lat_deg = 38;
  globe.altitude_m = views::globe_altitude(g, 1.2, height, globe.fov_y);
  globe.heading = -0.5;
  globe.tilt = 0.85 * views::limb_angle(globe.altitude_m);  // the centre ray still meets the sphere
  out.push_back({"globe oblique (" + views::fixed(globe.tilt, 2) + " rad, 85% of the limb)",
                 std::make_shared<GlobeScene>(globe, g.width(), g.height()), true});
  if (quick) return out;
  out.push_back({"plane turned (tilt 0.6)",
                 std::make_shared<PlaneScene>(PlaneView{.center_u = 0.63 * W,
                                                        .center_v = 0.38 * H,
                                                        .texels_per_pixel = 1.1,
                                                        .heading = 2.1,
                                                        .tilt = 0.6}),
                 false});
  out.push_back({"plane grazing (tilt 1.35)",
                 std::make_shared<PlaneScene>(PlaneView{.center_u = 0.35 * W,
                                                        .center_v = 0.6 * H,
                                                        .texels_per_pixel = 0.7,
                                                        .heading = -1.2,
                                                        .tilt = 1.35}),
                 true});
  GlobeView far;
  far.lon_deg = -70;
  far.lat_deg = -15;
  far.altitude_m = views::globe_altitude(g, 3.0, height, far.fov_y);
  out.push_back({"globe far (3 texel/px at the nadir)",
                 std::make_shared<GlobeScene>(far, g.width(), g.height()), false});
  return out;
}

}  // namespace

Result<AccuracyTable> filtering_table(const AccuracyContext& ctx) {
  const int w = ctx.width, h = ctx.height;
  if (w < 16 || h < 16 || w * kSuperFactor > 16384 || h * kSuperFactor > 16384) {
    return Error{ErrorCode::invalid_argument, "filtering table: the viewport " + std::to_string(w) +
                                                  "x" + std::to_string(h) + " is outside 16 to " +
                                                  std::to_string(16384 / kSuperFactor) +
                                                  " pixels a side"};
  }
  if (Status s = views::need_gl_context("filtering table"); !s) return s.error();
  auto sampler = PyramidSampler::open(ctx.archive, 256);
  if (!sampler) return filtering_fail(sampler.error(), "cannot read " + ctx.archive.string());
  const Geometry g = (*sampler)->geometry();
  const std::vector<views::View> views = filtering_views(g, h, ctx.quick);
  const int timed_frames = ctx.quick ? 5 : 21;
  const std::size_t oblique = 1;  // index of the designated oblique view

  // 1. The ground truth of every view.
  std::vector<Image> truth;
  std::vector<std::vector<std::uint8_t>> masks;
  double truth_ms = 0;
  for (std::size_t v = 0; v < views.size(); ++v) {
    ctx.say("filtering: supersampled reference of " + views[v].name + " (" + std::to_string(v + 1) +
            " of " + std::to_string(views.size()) + ")");
    const auto t0 = Clock::now();
    auto ref = render_supersampled(**sampler, *views[v].scene, w, h, kSuperFactor);
    if (!ref) return filtering_fail(ref.error(), "reference of " + views[v].name);
    truth_ms += views::ms_since(t0);
    truth.push_back(std::move(*ref));
    masks.push_back(views::textured_mask(*views[v].scene, g, w, h));
  }
  Image truth64;  // of the oblique view; empty when the viewport is too large for it
  if (w * kFineFactor <= 16384 && h * kFineFactor <= 16384) {
    ctx.say("filtering: 64-sample reference of " + views[oblique].name);
    const auto t0 = Clock::now();
    auto ref = render_supersampled(**sampler, *views[oblique].scene, w, h, kFineFactor);
    if (!ref) return filtering_fail(ref.error(), "64-sample reference of " + views[oblique].name);
    truth_ms += views::ms_since(t0);
    truth64 = std::move(*ref);
  }

  // 2. Every mode on every view.
  struct ModeResult {
    views::ErrorSum all;
    std::vector<views::ErrorSum> per_view;
    views::ErrorSum oblique64;     // the oblique view against the 64-sample truth
    std::vector<double> frame_ms;  // per view: median of the timed frames
    double wanted = 0;             // mean FrameStats::wanted over the views
    std::uint64_t upload_bytes = 0;
    double max_bias = 0;
  };
  std::vector<ModeResult> results(kModeCount);
  std::vector<std::unique_ptr<VirtualTexture>> textures;  // one per mode, kept for the timing
  for (int m = 0; m < kModeCount; ++m) {
    const Mode& mode = kModes[m];
    ModeResult& r = results[std::size_t(m)];
    VirtualTextureOptions o;
    o.trilinear = mode.trilinear;
    o.anisotropy = mode.anisotropy;
    auto opened = views::open_vt(ctx.archive, o);
    if (!opened) {
      return filtering_fail(opened.error(),
                            "cannot open a virtual texture on " + ctx.archive.string());
    }
    textures.push_back(std::move(*opened));
    VirtualTexture& vt = *textures.back();
    for (std::size_t v = 0; v < views.size(); ++v) {
      ctx.say(std::string("filtering: ") + mode.name + " on " + views[v].name);
      const views::Convergence c = views::converge(vt, *views[v].scene, w, h, 1000);
      if (!c.complete) {
        return Error{ErrorCode::internal, std::string("filtering table: ") + mode.name + " on " +
                                              views[v].name + " never converged in " +
                                              std::to_string(c.frames) +
                                              " frames: " + views::describe(c.last)};
      }
      r.upload_bytes += c.upload_bytes;
      r.wanted += double(c.last.wanted) / double(views.size());
      r.max_bias = std::max(r.max_bias, c.last.mip_bias);
      const Image img = vt.read_image();
      views::ErrorSum e;
      if (!e.add(img, truth[v], masks[v])) {
        return Error{ErrorCode::internal,
                     "filtering table: the frame and the reference differ in size"};
      }
      r.all.add(e);
      r.per_view.push_back(e);
      if (v == oblique && !truth64.rgba.empty() && !r.oblique64.add(img, truth64, masks[v])) {
        return Error{ErrorCode::internal,
                     "filtering table: the frame and the 64-sample reference differ in size"};
      }
    }
  }

  // 3. Frame time of each converged view; the modes take turns frame by frame, so a load
  // elsewhere on the machine falls on all alike.
  for (std::size_t v = 0; v < views.size(); ++v) {
    ctx.say("filtering: timing " + views[v].name);
    const Scene& scene = *views[v].scene;
    for (auto& vt : textures) (void)views::converge(*vt, scene, w, h, 1000);
    std::vector<std::vector<double>> ms(kModeCount);
    for (int i = 0; i < timed_frames; ++i) {
      for (int m = 0; m < kModeCount; ++m) {
        ms[std::size_t(m)].push_back(views::timed_frame(*textures[std::size_t(m)], scene, w, h).ms);
      }
    }
    for (int m = 0; m < kModeCount; ++m) {
      results[std::size_t(m)].frame_ms.push_back(views::median(ms[std::size_t(m)]));
    }
  }
  textures.clear();

  // 4. The table.
  AccuracyTable t;
  t.id = "filtering";
  t.title = "Filtering: error against a 16x supersampled reference vs frame time";
  t.columns = {
      {"mode", "filtering", 0},
      {"max_taps", "max taps", 0},
      {"psnr_db", "PSNR (dB)", 2},
      {"psnr_oblique_db", "PSNR oblique (dB)", 2},
      {"psnr_oblique_64_db", "PSNR oblique, 64-sample truth (dB)", 2},
      {"mean_abs", "mean |error|", 3},
      {"max_abs", "max |error|", 0},
      {"frame_ms", "frame (ms)", 2},
      {"time_vs_trilinear", "time x trilinear", 2},
      {"tiles_wanted", "tiles wanted", 1},
      {"upload_mb", "uploaded (MB)", 2},
  };
  const double tri_ms = views::mean(results[kTrilinear].frame_ms);
  for (int m = 0; m < kModeCount; ++m) {
    const ModeResult& r = results[std::size_t(m)];
    const double ms = views::mean(r.frame_ms);
    t.rows.push_back({
        std::string(kModes[m].name),
        double(kModes[m].anisotropy),
        r.all.psnr_db(),
        r.per_view.size() > oblique ? r.per_view[oblique].psnr_db() : kNotMeasured,
        r.oblique64.psnr_db(),
        r.all.mean_abs(),
        double(r.all.max),
        ms,
        tri_ms > 0 ? ms / tri_ms : kNotMeasured,
        r.wanted,
        double(r.upload_bytes) / 1e6,
    });
  }

  std::string names;
  for (const auto& v : views) names += (names.empty() ? "" : ", ") + v.name;
  t.notes = {
      "Viewport " + std::to_string(w) + "x" + std::to_string(h) + "; archive " +
          ctx.archive.filename().string() + " (" + std::to_string(g.width()) + "x" +
          std::to_string(g.height()) + ", tile " + std::to_string(g.tile_size()) + "); " +
          std::to_string(views.size()) + " views: " + names + ".",
      "Modes: bilinear = VirtualTextureOptions::trilinear false (one bilinear sample at the "
      "finer of the two levels around the footprint's level); trilinear = two bilinear samples "
      "blended; anisotropic N = up to N trilinear taps along the footprint's major axis "
      "(VirtualTextureOptions::anisotropy), the level chosen for one tap.",
      "Error: each view converged (FrameStats::complete, feedback 1/8, mip bias 0 unless noted), "
      "its frame read back and compared with the reference renderer's render_supersampled() of "
      "the same view at factor " +
          std::to_string(kSuperFactor) + " (" + std::to_string(kSuperFactor * kSuperFactor) +
          " samples per pixel, each at its own finer level, averaged in linear light): the "
          "ground truth of what the pixel covers. R, G, B of the pixels whose centre sees the "
          "image, pooled over all views: PSNR = 10 log10(255^2 / MSE), mean and max |error| "
          "in 8-bit sRGB steps. 'PSNR oblique' is the " +
          views[oblique].name + " view alone. A " + std::to_string(kSuperFactor * kSuperFactor) +
          "-sample truth takes " + std::to_string(kSuperFactor) +
          " samples along the footprint's long axis, as " + std::to_string(kSuperFactor) +
          " anisotropic taps do: it cannot rank more taps than that and flatters exactly " +
          std::to_string(kSuperFactor) + ", so the oblique view is also compared with " +
          std::to_string(kFineFactor * kFineFactor) + " samples per pixel (factor " +
          std::to_string(kFineFactor) + "; n/a when the viewport is over " +
          std::to_string(16384 / kFineFactor) + " pixels a side). References took " +
          views::fixed(truth_ms / 1000, 1) + " s on the CPU.",
      "Time: render() + glFinish() of the converged view (colour pass, 1/8 feedback pass, VT CPU "
      "work; nothing streams), the median of " +
          std::to_string(timed_frames) +
          " frames per view (the modes taking turns frame by frame), averaged over the views; "
          "under Mesa llvmpipe the GPU is the CPU. "
          "'time x trilinear' divides by the trilinear figure.",
      "Bytes: tiles wanted is FrameStats::wanted (ancestors included) once converged, averaged "
      "over the views (finer levels cost tiles); uploaded is the tile data copied into the "
      "physical texture to converge every view in turn from a cold client.",
  };
  for (int m = 0; m < kModeCount; ++m) {
    if (results[std::size_t(m)].max_bias > 0) {
      t.notes.push_back(std::string(kModes[m].name) + ": the mip bias was " +
                        views::fixed(results[std::size_t(m)].max_bias, 1) +
                        " on some view (more tiles wanted than slots).");
    }
  }

  TablePlot plot;
  plot.id = "filtering-error-time";
  plot.title = "Filtering: PSNR against the supersampled reference vs frame time";
  plot.x_label = "frame time (ms, llvmpipe)";
  plot.y_label = "PSNR (dB)";
  PlotSeries all{"all views", {}}, obl{views[oblique].name, {}},
      obl64{views[oblique].name + ", 64-sample truth", {}};
  for (int m = 0; m < kModeCount; ++m) {
    const ModeResult& r = results[std::size_t(m)];
    const double x = views::mean(r.frame_ms);
    if (std::isfinite(x) && std::isfinite(r.all.psnr_db())) {
      all.points.emplace_back(x, r.all.psnr_db());
      all.labels.emplace_back(kModes[m].name);
    }
    if (std::isfinite(x) && r.per_view.size() > oblique &&
        std::isfinite(r.per_view[oblique].psnr_db()))
      obl.points.emplace_back(x, r.per_view[oblique].psnr_db());
    if (std::isfinite(x) && std::isfinite(r.oblique64.psnr_db()))
      obl64.points.emplace_back(x, r.oblique64.psnr_db());
  }
  plot.series = {all, obl};
  if (!obl64.points.empty()) plot.series.push_back(obl64);
  t.plots.push_back(plot);
  return t;
}

}  // namespace vts::accuracy
