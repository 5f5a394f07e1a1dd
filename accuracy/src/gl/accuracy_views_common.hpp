// Shared by the feedback and filtering tables of `vts bench accuracy` (accuracy_feedback.cpp,
// accuracy_filtering.cpp): a VirtualTexture over the real client stack on a local archive, views of
// the plane and the globe (some oblique) placed on any image, convergence loops, and image error
// over the pixels that show the image. Private to vts::accuracy; the functions that need the
// current GL context say so.
#pragma once

#include <epoxy/gl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <numbers>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/globe.hpp"
#include "vts/renderer/reference.hpp"
#include "vts/renderer/scene.hpp"
#include "vts/renderer/virtual_texture.hpp"

namespace vts::accuracy::views {

using Clock = std::chrono::steady_clock;

inline double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The median (upper median for an even count); NaN for none.
inline double median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

inline double mean(const std::vector<double>& v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  double s = 0;
  for (double x : v) s += x;
  return s / double(v.size());
}

// splitmix64: the same places on every platform.
struct Rng {
  std::uint64_t state;
  std::uint64_t next() {
    std::uint64_t z = (state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  double uniform(double lo, double hi) { return lo + (hi - lo) * double(next() >> 11) * 0x1p-53; }
};

// The angle between the nadir and the limb seen from `altitude_m` above the sphere.
inline double limb_angle(double altitude_m) {
  return std::asin(renderer::kEarthRadiusM / (renderer::kEarthRadiusM + altitude_m));
}

// A view of the benchmark: the scene and how it was placed.
struct View {
  std::string name;  // "plane oblique (tilt 1.15)"
  std::shared_ptr<const renderer::Scene> scene;
  bool oblique = false;  // tilted far enough that the footprint is long (anisotropy matters)
};

enum class ViewKind { plane_straight, plane_turned, plane_oblique, globe_far, globe_oblique };
inline constexpr int kViewKinds = 5;

// The altitude at which the globe's nadir shows `tpp` finest texels per pixel in a view `height`
// pixels tall with vertical field of view fov_y.
inline double globe_altitude(const Geometry& g, double tpp, int height, double fov_y) {
  const double texel_m = 2 * std::numbers::pi * renderer::kEarthRadiusM / double(g.width());
  return tpp * texel_m * double(height) / (2 * std::tan(fov_y / 2));
}

// A view of kind `kind` at a place and zoom drawn from `rng`, for an image of geometry g seen in a
// viewport `height` pixels tall. Plane views are centred in the middle half of the image; zooms
// stay within a level or so of the finest, where the filter and the feedback matter.
inline View make_view(ViewKind kind, Rng& rng, const Geometry& g, int height) {
  using renderer::GlobeScene;
  using renderer::GlobeView;
  using renderer::PlaneScene;
  using renderer::PlaneView;
  const double W = double(g.width()), H = double(g.height());
  const auto centre = [&](PlaneView& v) {
    v.center_u = rng.uniform(0.25, 0.75) * W;
    v.center_v = rng.uniform(0.25, 0.75) * H;
  };
  const auto fmt = [](double x) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.2f", x);
    return std::string(buf);
  };
  View out;
  // A plane view centred in the middle half at a zoom in [tpp_lo, tpp_hi); turned to a random
  // heading and tilted into [tilt_lo, tilt_hi) when tilt_hi > 0.
  const auto plane = [&](double tpp_lo, double tpp_hi, double tilt_lo, double tilt_hi) {
    PlaneView v;
    centre(v);
    v.texels_per_pixel = rng.uniform(tpp_lo, tpp_hi);
    if (tilt_hi > 0) {
      v.heading = rng.uniform(-std::numbers::pi, std::numbers::pi);
      v.tilt = rng.uniform(tilt_lo, tilt_hi);
    }
    out.scene = std::make_shared<PlaneScene>(v);
    return v;
  };
  switch (kind) {
    case ViewKind::plane_straight:
      out.name = "plane straight (" + fmt(plane(0.7, 2.6, 0, 0).texels_per_pixel) + " texel/px)";
      break;
    case ViewKind::plane_turned:
      out.name = "plane turned (tilt " + fmt(plane(0.6, 2.0, 0.3, 0.7).tilt) + ")";
      break;
    case ViewKind::plane_oblique:
      out.name = "plane oblique (tilt " + fmt(plane(0.8, 1.6, 1.0, 1.2).tilt) + ")";
      out.oblique = true;
      break;
    case ViewKind::globe_far: {
      GlobeView v;
      v.lon_deg = rng.uniform(-180, 180);
      v.lat_deg = rng.uniform(-50, 50);
      v.altitude_m = globe_altitude(g, rng.uniform(2.0, 5.0), height, v.fov_y);
      out.name = "globe far (" + fmt(v.altitude_m / 1000) + " km)";
      out.scene = std::make_shared<GlobeScene>(v, g.width(), g.height());
      break;
    }
    case ViewKind::globe_oblique: {
      GlobeView v;
      v.lon_deg = rng.uniform(-180, 180);
      v.lat_deg = rng.uniform(-60, 60);
      v.altitude_m = globe_altitude(g, rng.uniform(0.8, 1.6), height, v.fov_y);
      v.heading = rng.uniform(-std::numbers::pi, std::numbers::pi);
      // Far enough from the limb that the centre ray meets the sphere (a coarse image is seen from
      // high up, where the limb is close to the nadir).
      v.tilt = std::min(rng.uniform(0.8, 1.05), rng.uniform(0.7, 0.85) * limb_angle(v.altitude_m));
      out.name = "globe oblique (tilt " + fmt(v.tilt) + ")";
      out.scene = std::make_shared<GlobeScene>(v, g.width(), g.height());
      out.oblique = true;
      break;
    }
  }
  return out;
}

// Error when no OpenGL context (GLFW's or EGL's) is current on the calling thread (GlContext makes
// one current):
// without it the first GL call would not fail cleanly.
inline Status need_gl_context(const std::string& table) {
  if (!renderer::GlContext::any_current()) {
    return Error{ErrorCode::unsupported,
                 table + ": needs a current OpenGL 4.5 core context on the calling thread"};
  }
  return {};
}

// The tileset's geometry, read from the archive's metadata.
inline Result<Geometry> archive_geometry(const std::filesystem::path& archive) {
  auto sampler = renderer::PyramidSampler::open(archive, 1);
  if (!sampler) return sampler.error();
  return (*sampler)->geometry();
}

// A VirtualTexture reading `archive` through a local source and its own TileClient (decode pool,
// RAM cache): every call starts cold. Needs the GL context.
inline Result<std::unique_ptr<renderer::VirtualTexture>> open_vt(
    const std::filesystem::path& archive, const renderer::VirtualTextureOptions& options) {
  auto src = client::open_local_archive(archive);
  if (!src) return src.error();
  auto tiles = client::TileClient::create(std::shared_ptr(std::move(*src)));
  if (!tiles) return tiles.error();
  const Geometry geometry = (*tiles)->info().info.geometry;
  return renderer::VirtualTexture::create(std::shared_ptr(std::move(*tiles)), geometry, options);
}

// One frame of `scene` finished on the GPU (glFinish), and its wall time. Needs the GL context.
struct TimedFrame {
  renderer::FrameStats stats;
  double ms = 0;
};
inline TimedFrame timed_frame(renderer::VirtualTexture& vt, const renderer::Scene& scene, int w,
                              int h) {
  const auto t0 = Clock::now();
  TimedFrame f{vt.render(scene, w, h), 0};
  glFinish();
  f.ms = ms_since(t0);
  return f;
}

struct Convergence {
  bool complete = false;
  int frames = 0;  // render() calls until the first complete frame (or all made, if never)
  double ms = 0;   // wall time of those frames
  std::uint64_t upload_bytes = 0;
  renderer::FrameStats last;
};

// A frame's streaming state, for error messages.
inline std::string describe(const renderer::FrameStats& st) {
  return std::to_string(st.wanted) + " tiles wanted, " + std::to_string(st.wanted_missing) +
         " missing, " + std::to_string(st.pending) + " pending, " + std::to_string(st.resident) +
         " resident, " + std::to_string(st.refusals) + " refusals, " + std::to_string(st.errors) +
         " errors, mip bias " + std::to_string(st.mip_bias);
}

// Renders `scene` until a frame is complete or max_frames were made; each frame is finished on
// the GPU (glFinish). When the client still owes tiles the loop gives its decode threads a
// millisecond. Needs the GL context.
inline Convergence converge(renderer::VirtualTexture& vt, const renderer::Scene& scene, int w,
                            int h, int max_frames) {
  Convergence c;
  const auto t0 = Clock::now();
  for (int i = 1; i <= max_frames; ++i) {
    c.last = vt.render(scene, w, h);
    glFinish();
    c.frames = i;
    c.upload_bytes += c.last.upload_bytes;
    if (c.last.complete) {
      c.complete = true;
      break;
    }
    if (c.last.pending > 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  c.ms = ms_since(t0);
  return c;
}

// Which pixels of a width x height view show the image (their centre's ray hits it): the error
// figures are taken over these only, so a sky or a background that every filter draws alike does
// not dilute them.
inline std::vector<std::uint8_t> textured_mask(const renderer::Scene& scene, const Geometry& g,
                                               int width, int height) {
  std::vector<std::uint8_t> mask(std::size_t(width) * std::size_t(height), 0);
  const double W = double(g.width()), H = double(g.height());
  const bool wraps = scene.u_period() > 0;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const renderer::UvHit hit = scene.hit(x + 0.5, y + 0.5, width, height);
      if (!hit || !std::isfinite(hit->first) || !std::isfinite(hit->second)) continue;
      const bool inside =
          (wraps || (hit->first >= 0 && hit->first < W)) && hit->second >= 0 && hit->second < H;
      mask[std::size_t(y) * width + x] = inside ? 1 : 0;
    }
  }
  return mask;
}

// Accumulated R, G, B differences between images over masked pixels, pooled over any number of
// image pairs.
struct ErrorSum {
  double sq = 0, abs = 0;
  int max = 0;
  std::uint64_t values = 0;  // channel values compared (3 per pixel)

  // false when the sizes do not match.
  bool add(const renderer::Image& a, const renderer::Image& b,
           const std::vector<std::uint8_t>& mask) {
    if (a.width != b.width || a.height != b.height ||
        a.rgba.size() != std::size_t(a.width) * std::size_t(a.height) * 4 ||
        b.rgba.size() != a.rgba.size() || mask.size() != std::size_t(a.width) * a.height)
      return false;
    for (std::size_t p = 0; p < mask.size(); ++p) {
      if (!mask[p]) continue;
      for (int ch = 0; ch < 3; ++ch) {
        const int d = std::abs(int(a.rgba[p * 4 + ch]) - int(b.rgba[p * 4 + ch]));
        sq += double(d) * d;
        abs += d;
        max = std::max(max, d);
        ++values;
      }
    }
    return true;
  }
  void add(const ErrorSum& o) {
    sq += o.sq;
    abs += o.abs;
    max = std::max(max, o.max);
    values += o.values;
  }
  // 10 log10(255^2 / MSE); +inf when equal, NaN when nothing was compared.
  double psnr_db() const {
    if (values == 0) return std::numeric_limits<double>::quiet_NaN();
    if (sq == 0) return std::numeric_limits<double>::infinity();
    return 10 * std::log10(255.0 * 255.0 / (sq / double(values)));
  }
  double mean_abs() const {
    return values ? abs / double(values) : std::numeric_limits<double>::quiet_NaN();
  }
};

// Pixels (within the mask) whose largest R, G, B difference exceeds `threshold`; SIZE_MAX when
// the sizes differ.
inline std::size_t pixels_over(const renderer::Image& a, const renderer::Image& b,
                               const std::vector<std::uint8_t>& mask, int threshold) {
  if (a.width != b.width || a.height != b.height || a.rgba.size() != b.rgba.size() ||
      mask.size() * 4 != a.rgba.size())
    return std::numeric_limits<std::size_t>::max();
  std::size_t n = 0;
  for (std::size_t p = 0; p < mask.size(); ++p) {
    if (!mask[p]) continue;
    for (int ch = 0; ch < 3; ++ch) {
      if (std::abs(int(a.rgba[p * 4 + ch]) - int(b.rgba[p * 4 + ch])) > threshold) {
        ++n;
        break;
      }
    }
  }
  return n;
}

inline std::string fixed(double x, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, x);
  return buf;
}

}  // namespace vts::accuracy::views
