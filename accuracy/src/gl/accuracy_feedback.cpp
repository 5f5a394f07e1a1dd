// Table: feedback (accuracy/include/vts/accuracy/accuracy.hpp). What the resolution of the feedback
// pass (1/1 ... 1/16 of the screen) costs in missed tiles, in frames to convergence after a jump,
// and saves in CPU time and readback bytes per frame.
//
// Two measurements:
//   - tiles found: the CPU demand simulator (renderer/demand.hpp: the GPU feedback pass pixel for
//     pixel, reduced by the renderer's own FeedbackProcessor) on many seeded views of the plane and
//     the globe, compared with what the 1/1 feedback of the same view asks for;
//   - convergence, CPU and frame time: a real VirtualTexture over a real TileClient on the local
//     archive, jumping between seeded views at a paced 60 Hz, each divisor from a cold client.
#include <epoxy/gl.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <thread>
#include <unordered_set>
#include <vector>

#include "accuracy_views_common.hpp"
#include "vts/accuracy/accuracy.hpp"
#include "vts/renderer/demand.hpp"
#include "vts/renderer/feedback.hpp"
#include "vts/renderer/pyramid.hpp"

namespace vts::accuracy {

namespace {

using namespace vts::renderer;
using views::Clock;

constexpr int kDivisors[] = {1, 2, 4, 8, 16};
constexpr int kFeedbackModes = 5;
constexpr double kFramePeriodMs = 1000.0 / 60.0;
constexpr double kInf = std::numeric_limits<double>::infinity();

Error feedback_fail(const Error& e, const std::string& what) {
  return Error{e.code, "feedback table: " + what + ": " + e.message};
}

// What the simulator says about one divisor, over all views.
struct FoundStats {
  std::vector<double> tiles_found;   // per view: share of the 1/1 direct tiles in the 1/k set
  std::vector<double> pixels_found;  // per view: share of textured 1/1 pixels whose tile is in it
  std::vector<double> reduce_ms;     // per view: FeedbackProcessor::process() alone
  std::vector<double> requested;     // per view: tiles requested (ancestors included)
};

// What the GPU runs say about one divisor.
struct JumpStats {
  std::vector<double> frames_complete, ms_complete, frames_full;
  int jumps = 0, completed = 0, reached_full = 0;
  views::ErrorSum at_complete;  // the complete frame against the 1/1 complete frame
  std::vector<double> cpu_ms, frame_ms;
  double max_bias = 0;
  std::uint64_t upload_bytes = 0;
};

std::uint64_t readback_bytes(int w, int h, int k) {
  const std::uint64_t fw = std::uint64_t(std::max(1, (w + k - 1) / k));
  const std::uint64_t fh = std::uint64_t(std::max(1, (h + k - 1) / k));
  return fw * fh * 8;
}

}  // namespace

Result<AccuracyTable> feedback_table(const AccuracyContext& ctx) {
  const int w = ctx.width, h = ctx.height;
  if (w < 16 || h < 16 || w > 16384 || h > 16384) {
    return Error{ErrorCode::invalid_argument, "feedback table: the viewport " + std::to_string(w) +
                                                  "x" + std::to_string(h) +
                                                  " is outside 16 to 16384 pixels a side"};
  }
  if (Status s = views::need_gl_context("feedback table"); !s) return s.error();
  auto geometry = views::archive_geometry(ctx.archive);
  if (!geometry) return feedback_fail(geometry.error(), "cannot read " + ctx.archive.string());
  const Geometry g = *geometry;
  auto pyramid = Pyramid::from_geometry(g);
  if (!pyramid) return feedback_fail(pyramid.error(), "the archive's pyramid");

  const int sim_views = ctx.quick ? 20 : 40;
  const int jumps = ctx.quick ? 5 : 10;
  const int steady_frames = ctx.quick ? 4 : 12;  // per timed view
  const int max_frames = ctx.quick ? 60 : 120;   // per jump
  const int settle_frames = 8;  // frames after `complete` to wait for the 1/1 image

  // 1. Tiles found, from the demand simulator.
  FoundStats found[kFeedbackModes];
  {
    views::Rng rng{0xfeedbac5ull};
    for (int i = 0; i < sim_views; ++i) {
      const views::View view = views::make_view(views::ViewKind(i % views::kViewKinds), rng, g, h);
      if (i % 5 == 0) {
        ctx.say("feedback: simulated demand, view " + std::to_string(i + 1) + " of " +
                std::to_string(sim_views));
      }
      std::unordered_set<std::uint64_t> needed;  // 1/1 direct tiles
      std::vector<std::uint64_t> pixel_tiles;    // the tile of each textured 1/1 pixel
      for (int m = 0; m < kFeedbackModes; ++m) {
        const int k = kDivisors[m];
        auto buffer = simulate_feedback(*view.scene, g, w, h, DemandOptions{k, 1});
        if (!buffer) return feedback_fail(buffer.error(), "simulated feedback of " + view.name);
        FeedbackProcessor processor(*pyramid);
        Result<std::vector<TileRequest>> requests = std::vector<TileRequest>{};
        double best = kInf;
        for (int rep = 0; rep < 3; ++rep) {
          const auto t0 = Clock::now();
          requests = processor.process(*buffer, 0);
          best = std::min(best, views::ms_since(t0));
          if (!requests)
            return feedback_fail(requests.error(), "feedback reduction of " + view.name);
        }
        if (k == 1) {
          for (const TileRequest& r : *requests)
            if (r.direct) needed.insert(tile_key(r.tile));
          for (std::size_t p = 0; p + 1 < buffer->size(); p += 2) {
            const auto t = processor.requested_tile((*buffer)[p], (*buffer)[p + 1], 0);
            if (t) pixel_tiles.push_back(tile_key(*t));
          }
        }
        if (needed.empty()) break;  // nothing of the image in view: not a view to judge
        std::unordered_set<std::uint64_t> got;
        for (const TileRequest& r : *requests) got.insert(tile_key(r.tile));
        std::size_t tiles_hit = 0, pixels_hit = 0;
        for (std::uint64_t t : needed) tiles_hit += got.count(t);
        for (std::uint64_t t : pixel_tiles) pixels_hit += got.count(t);
        found[m].tiles_found.push_back(double(tiles_hit) / double(needed.size()));
        found[m].pixels_found.push_back(
            pixel_tiles.empty() ? 1.0 : double(pixels_hit) / double(pixel_tiles.size()));
        found[m].reduce_ms.push_back(best);
        found[m].requested.push_back(double(requests->size()));
      }
    }
  }
  if (found[0].tiles_found.empty()) {
    return Error{
        ErrorCode::invalid_argument,
        "feedback table: none of the views shows the image (" + ctx.archive.string() + ")"};
  }

  // 2. Jumps on the GPU. The same seeded start and targets for every divisor.
  views::Rng rng{0x1a3b5c7dull};
  const views::View start = views::make_view(views::ViewKind::plane_straight, rng, g, h);
  std::vector<views::View> targets;
  const views::ViewKind order[] = {views::ViewKind::plane_oblique, views::ViewKind::globe_oblique,
                                   views::ViewKind::plane_turned, views::ViewKind::globe_far,
                                   views::ViewKind::plane_straight};
  for (int j = 0; j < jumps; ++j) targets.push_back(views::make_view(order[j % 5], rng, g, h));
  std::vector<std::vector<std::uint8_t>> masks;
  for (const auto& t : targets) masks.push_back(views::textured_mask(*t.scene, g, w, h));
  // Compiles the globe's shader variant before the jumps, wanting only the coarsest tiles, which
  // every view wants anyway.
  GlobeView whole;
  whole.altitude_m = views::globe_altitude(g, 64.0 * double(g.tile_size()), h, whole.fov_y);
  const GlobeScene warm_globe(whole, g.width(), g.height());

  std::vector<Image> full(
      static_cast<std::size_t>(jumps));  // the 1/1 complete frame of each target
  JumpStats runs[kFeedbackModes];
  std::vector<std::unique_ptr<VirtualTexture>> textures;  // one per divisor, kept for the timing
  for (int m = 0; m < kFeedbackModes; ++m) {
    const int k = kDivisors[m];
    JumpStats& run = runs[m];
    VirtualTextureOptions o;
    o.feedback_divisor = k;
    auto opened = views::open_vt(ctx.archive, o);
    if (!opened) {
      return feedback_fail(opened.error(),
                           "cannot open a virtual texture on " + ctx.archive.string());
    }
    textures.push_back(std::move(*opened));
    VirtualTexture* vt = textures.back().get();
    (void)vt->render(warm_globe, w, h);
    const views::Convergence first = views::converge(*vt, *start.scene, w, h, 600);
    if (!first.complete) {
      return Error{ErrorCode::internal,
                   "feedback table: 1/" + std::to_string(k) +
                       ": the start view never converged: " + views::describe(first.last)};
    }
    for (int j = 0; j < jumps; ++j) {
      ctx.say("feedback: 1/" + std::to_string(k) + ": jump " + std::to_string(j + 1) + " of " +
              std::to_string(jumps) + " to " + targets[std::size_t(j)].name);
      const Scene& scene = *targets[std::size_t(j)].scene;
      const auto& mask = masks[std::size_t(j)];
      Image& reference = full[std::size_t(j)];
      const bool judged = k == 1 || !reference.rgba.empty();
      int complete_at = 0, full_at = 0;
      std::vector<Image> history;  // 1/1: every frame of the jump, until it completes
      const auto t_jump = Clock::now();
      for (int i = 1; i <= max_frames; ++i) {
        const auto t0 = Clock::now();
        const FrameStats st = vt->render(scene, w, h);
        glFinish();
        run.max_bias = std::max(run.max_bias, st.mip_bias);
        run.upload_bytes += st.upload_bytes;
        // Every frame is read back at every divisor, so each pays the same for being watched.
        Image img = vt->read_image();
        if (st.complete && !complete_at) {
          complete_at = i;
          run.frames_complete.push_back(i);
          run.ms_complete.push_back(views::ms_since(t_jump));
          if (k == 1) {
            // The 1/1 image: the first frame that already looked like the complete one.
            reference = img;
            history.push_back(img);
            for (std::size_t f = 0; f < history.size() && !full_at; ++f) {
              if (views::pixels_over(history[f], reference, mask, 2) == 0) full_at = int(f) + 1;
            }
            history.clear();
          }
          if (judged) (void)run.at_complete.add(img, reference, mask);
        }
        if (k == 1 && !complete_at) history.push_back(std::move(img));
        if (k > 1 && judged && !full_at && views::pixels_over(img, reference, mask, 2) == 0)
          full_at = i;
        if (complete_at && (full_at || !judged || i >= complete_at + settle_frames)) break;
        const double spent = views::ms_since(t0);
        if (spent < kFramePeriodMs) {
          std::this_thread::sleep_for(
              std::chrono::duration<double, std::milli>(kFramePeriodMs - spent));
        }
      }
      ++run.jumps;
      if (complete_at) ++run.completed;
      if (judged && full_at) {
        ++run.reached_full;
        run.frames_full.push_back(full_at);
      }
    }
  }

  // 3. Converged frames, unpaced: what the feedback costs every frame once nothing streams. The
  // divisors take turns frame by frame, so a load elsewhere on the machine falls on all alike.
  const int timed_views = std::min(jumps, ctx.quick ? 3 : 5);
  for (int j = 0; j < timed_views; ++j) {
    ctx.say("feedback: timing converged frames on " + targets[std::size_t(j)].name);
    const Scene& scene = *targets[std::size_t(j)].scene;
    for (auto& vt : textures) (void)views::converge(*vt, scene, w, h, max_frames);
    for (int i = 0; i < steady_frames; ++i) {
      for (int m = 0; m < kFeedbackModes; ++m) {
        const auto [st, ms] = views::timed_frame(*textures[std::size_t(m)], scene, w, h);
        runs[m].frame_ms.push_back(ms);
        if (st.feedback_frames > 0 && st.uploads == 0) runs[m].cpu_ms.push_back(st.vt_cpu_ms);
      }
    }
  }
  textures.clear();

  // 4. The table.
  AccuracyTable t;
  t.id = "feedback";
  t.title = "Feedback resolution: needed tiles found, convergence after a jump, CPU per frame";
  t.columns = {
      {"divisor", "feedback 1/k", 0},
      {"feedback_px", "feedback pixels", 0},
      {"readback_bytes", "readback (bytes/frame)", 0},
      {"tiles_found", "needed tiles found", 3},
      {"tiles_found_min", "worst view", 3},
      {"pixels_full_res", "pixels at full res", 4},
      {"frames_to_complete", "frames to complete", 1},
      {"ms_to_complete", "ms to complete", 0},
      {"frames_to_full_image", "frames to 1/1 image", 1},
      {"jumps_full_image", "jumps reaching 1/1 image", 0},
      {"psnr_at_complete_db", "PSNR at complete vs 1/1 (dB)", 1},
      {"vt_cpu_ms", "VT CPU (ms/frame)", 3},
      {"reduce_ms", "reduction (ms)", 3},
      {"frame_ms", "frame (ms)", 2},
      {"tiles_requested", "tiles requested", 1},
      {"upload_mb", "uploaded in the jumps (MB)", 2},
  };
  std::vector<double> cpu_by_mode(kFeedbackModes), found_by_mode(kFeedbackModes),
      pixels_by_mode(kFeedbackModes);
  std::vector<double> frames_complete(kFeedbackModes), frames_full(kFeedbackModes);
  for (int m = 0; m < kFeedbackModes; ++m) {
    const int k = kDivisors[m];
    const FoundStats& f = found[m];
    const JumpStats& r = runs[m];
    const int fw = std::max(1, (w + k - 1) / k), fh = std::max(1, (h + k - 1) / k);
    found_by_mode[std::size_t(m)] = views::mean(f.tiles_found);
    pixels_by_mode[std::size_t(m)] = views::mean(f.pixels_found);
    cpu_by_mode[std::size_t(m)] = views::median(r.cpu_ms);
    frames_complete[std::size_t(m)] =
        r.completed == r.jumps ? views::mean(r.frames_complete) : kInf;
    const int judged = k == 1 ? r.jumps
                              : int(std::count_if(full.begin(), full.end(),
                                                  [](const Image& i) { return !i.rgba.empty(); }));
    frames_full[std::size_t(m)] = views::mean(r.frames_full);  // NaN when no jump reached it
    t.rows.push_back({
        double(k),
        std::to_string(fw) + "x" + std::to_string(fh),
        double(readback_bytes(w, h, k)),
        found_by_mode[std::size_t(m)],
        f.tiles_found.empty() ? kNotMeasured
                              : *std::min_element(f.tiles_found.begin(), f.tiles_found.end()),
        pixels_by_mode[std::size_t(m)],
        frames_complete[std::size_t(m)],
        r.completed == r.jumps ? views::mean(r.ms_complete) : kInf,
        frames_full[std::size_t(m)],
        std::to_string(r.reached_full) + " of " + std::to_string(judged),
        r.at_complete.psnr_db(),
        cpu_by_mode[std::size_t(m)],
        views::median(f.reduce_ms),
        views::median(r.frame_ms),
        views::mean(f.requested),
        double(r.upload_bytes) / 1e6,
    });
  }

  const std::string size = std::to_string(w) + "x" + std::to_string(h);
  t.notes = {
      "Viewport " + size + "; archive " + ctx.archive.filename().string() + " (" +
          std::to_string(g.width()) + "x" + std::to_string(g.height()) + ", tile " +
          std::to_string(g.tile_size()) + ", " + std::to_string(g.level_count()) +
          " levels); isotropic trilinear filtering (anisotropy 1), mip bias 0, 256 slots.",
      "feedback pixels / readback: the feedback target is ceil(w/k) x ceil(h/k) RG32UI pixels, "
      "8 bytes each, read back every frame through a pixel-pack buffer.",
      "needed tiles found: for " + std::to_string(found[0].tiles_found.size()) +
          " seeded views (plane straight, turned, oblique at tilt 1.0-1.2; globe far; globe "
          "oblique, "
          "tilted to 70-85% of the limb angle and at most 1.05 rad), the tiles the 1/1 feedback "
          "wants directly (the finest level some "
          "pixel samples) that the 1/k feedback also requests (directly or as an ancestor), as a "
          "share, averaged over the views; 'worst view' is the smallest share. Feedback from the "
          "CPU demand simulator (renderer/demand.hpp), which reproduces the GPU feedback pass "
          "pixel for pixel (tests/gl/test_demand.cpp) and is reduced by the renderer's own "
          "FeedbackProcessor.",
      "pixels at full res: the share of the textured 1/1 feedback pixels whose tile the 1/k "
      "feedback requests: the share of the screen drawn at full resolution once the 1/k set is "
      "resident (a pixel whose tile is missing falls back on an ancestor).",
      "frames / ms to complete: a real VirtualTexture (default options but the divisor) over a "
      "real TileClient (2 decode threads, a cold cache per divisor) on the local archive, "
      "converged on a start view, then " +
          std::to_string(jumps) +
          " jumps to seeded views (plane oblique, globe oblique, plane turned, globe far, plane "
          "straight, in turn). Frames are paced at 60 Hz (each frame rendered, finished with "
          "glFinish, then the rest of 16.7 ms slept) and counted from the first frame of the new "
          "view (1) to the first with FrameStats::complete (its own feedback of this view read "
          "back and every tile it wants resident); mean over the jumps, ms is the wall time. "
          "inf: some jump did not complete within " +
          std::to_string(max_frames) + " frames.",
      "frames to 1/1 image: frames until the frame equals the frame 1/1 feedback gives once "
      "complete (no textured pixel differs by more than 2 in any channel): the frame at which "
      "every tile the 1/1 feedback needs is resident. A jump that has not reached it " +
          std::to_string(settle_frames) +
          " frames after completing never does (its feedback no longer changes); the mean is over "
          "the jumps that reached it, which 'jumps "
          "reaching 1/1 image' counts. PSNR at complete: the "
          "first complete frame against that 1/1 frame over the textured pixels of every jump "
          "(inf: identical).",
      "VT CPU: median FrameStats::vt_cpu_ms of converged, unpaced frames (" +
          std::to_string(steady_frames) + " on each of the first " + std::to_string(timed_views) +
          " jump targets, the divisors taking turns frame by frame; frames that processed a "
          "feedback buffer and uploaded nothing): mapping the read-back buffer, FeedbackProcessor "
          "reduction, "
          "touching the wanted tiles, page-table recentring. reduction: FeedbackProcessor::"
          "process() alone on the simulated buffer, best of 3, median over the views. frame: "
          "median render() + glFinish() of those converged frames (the feedback pass itself "
          "runs on the CPU under llvmpipe). tiles requested: mean size of the 1/k request list "
          "(ancestors included) over the simulated views. uploaded in the jumps: tile bytes "
          "copied into the physical texture during the jumps (FrameStats::upload_bytes), the "
          "start view's excluded.",
  };
  for (int m = 0; m < kFeedbackModes; ++m) {
    if (runs[m].max_bias > 0) {
      t.notes.push_back("1/" + std::to_string(kDivisors[m]) + ": the mip bias rose to " +
                        views::fixed(runs[m].max_bias, 1) +
                        " during the jumps (more tiles wanted than slots).");
    }
  }

  TablePlot found_plot;
  found_plot.id = "feedback-found";
  found_plot.title = "Feedback resolution: needed tiles found vs VT CPU per frame (1/1 ... 1/16)";
  found_plot.x_label = "VT CPU per frame (ms)";
  found_plot.y_label = "share found (against 1/1)";
  PlotSeries tiles{"needed tiles found", {}}, pixels{"pixels at full resolution", {}};
  for (int m = 0; m < kFeedbackModes; ++m) {
    const double x = cpu_by_mode[std::size_t(m)];
    if (!std::isfinite(x)) continue;
    tiles.points.emplace_back(x, found_by_mode[std::size_t(m)]);
    tiles.labels.push_back("1/" + std::to_string(kDivisors[m]));
    pixels.points.emplace_back(x, pixels_by_mode[std::size_t(m)]);
  }
  found_plot.series = {tiles, pixels};
  t.plots.push_back(found_plot);

  TablePlot conv_plot;
  conv_plot.id = "feedback-convergence";
  conv_plot.title = "Feedback resolution: frames to convergence after a jump";
  conv_plot.x_label = "feedback divisor k (1/k resolution)";
  conv_plot.y_label = "frames (60 Hz)";
  conv_plot.log_x = true;
  PlotSeries complete{"frames to complete", {}}, to_full{"frames to the 1/1 image", {}};
  for (int m = 0; m < kFeedbackModes; ++m) {
    const double x = kDivisors[m];
    if (std::isfinite(frames_complete[std::size_t(m)]))
      complete.points.emplace_back(x, frames_complete[std::size_t(m)]);
    if (std::isfinite(frames_full[std::size_t(m)]))
      to_full.points.emplace_back(x, frames_full[std::size_t(m)]);
  }
  conv_plot.series = {complete, to_full};
  t.plots.push_back(conv_plot);
  return t;
}

}  // namespace vts::accuracy
