#include "vts/renderer/demand.hpp"

#include <bit>
#include <cmath>
#include <string>

#include "vts/renderer/footprint.hpp"

namespace vts::renderer {

namespace {

Status check_options(const DemandOptions& o) {
  const int k = o.feedback_divisor;
  if (k < 1 || k > 16 || !std::has_single_bit(unsigned(k)))
    return make_error(ErrorCode::invalid_argument,
                      "feedback divisor " + std::to_string(k) + " is not one of 1, 2, 4, 8, 16");
  if (o.anisotropy < 1 || o.anisotropy > 16)
    return make_error(ErrorCode::invalid_argument,
                      "anisotropy " + std::to_string(o.anisotropy) + " is outside 1 to 16 taps");
  return {};
}

}  // namespace

Result<std::vector<std::uint32_t>> simulate_feedback(const Scene& scene, const Geometry& geometry,
                                                     int width, int height,
                                                     const DemandOptions& options) {
  if (auto st = check_options(options); !st) return st.error();
  constexpr int kMaxSide = 1 << 14;
  if (width <= 0 || height <= 0 || width > kMaxSide || height > kMaxSide)
    return make_error(ErrorCode::invalid_argument,
                      "viewport " + std::to_string(width) + "x" + std::to_string(height) +
                          " is empty or larger than " + std::to_string(kMaxSide) + " a side");
  const int k = options.feedback_divisor;
  const int fb_w = std::max(1, (width + k - 1) / k), fb_h = std::max(1, (height + k - 1) / k);
  const double sx_scale = double(width) / fb_w, sy_scale = double(height) / fb_h;
  const int max_level = geometry.max_zoom();
  const int tile_shift = std::countr_zero(geometry.tile_size());
  // The feedback pass's level offset, in float as the GPU gets it.
  const double level_offset = double(float(std::log2(double(width) / fb_w)));

  std::vector<std::uint32_t> out(std::size_t(fb_w) * fb_h * 2, FeedbackPixel::kEmpty);
  const auto point_at = [&](double sx, double sy) {
    return scene_point(scene, sx * sx_scale, sy * sy_scale, width, height);
  };
  const auto fallback = [&](double sx, double sy, int axis) {
    auto d = scene_derivative(scene, sx * sx_scale, sy * sy_scale, width, height, axis);
    const double scale = axis == 0 ? sx_scale : sy_scale;
    return std::pair{d.first * scale, d.second * scale};
  };
  const auto visit = [&](const PixelFootprint& p) {
    const double lx = std::hypot(p.dudx, p.dvdx), ly = std::hypot(p.dudy, p.dvdy);
    const FootprintLevel fl = footprint_level(lx, ly, max_level, level_offset, options.anisotropy);
    const int L = int(std::ceil(fl.c));
    const auto f = std::uint32_t(std::min((L - fl.c) * 256.0, 255.0));
    const int s = max_level - L;
    const auto tx = std::uint32_t(std::uint64_t(p.u) >> s >> tile_shift);
    const auto ty = std::uint32_t(std::uint64_t(p.v) >> s >> tile_shift);
    FeedbackPixel::pack(L, tx, ty, f, out.data() + (std::size_t(p.y) * fb_w + p.x) * 2);
    return true;
  };
  const auto miss = [](int, int) { return true; };
  for_each_footprint(fb_w, fb_h, double(geometry.width()), double(geometry.height()),
                     scene.u_period(), point_at, fallback, visit, miss);
  return out;
}

Result<DemandSimulator> DemandSimulator::create(const Geometry& geometry, DemandOptions options) {
  if (auto st = check_options(options); !st) return st.error();
  auto pyramid = Pyramid::from_geometry(geometry);
  if (!pyramid) return pyramid.error();
  return DemandSimulator(geometry, *pyramid, options);
}

Result<std::vector<TileRequest>> DemandSimulator::demand(const Scene& scene, int width, int height,
                                                         double bias) {
  auto buffer = simulate_feedback(scene, geometry_, width, height, options_);
  if (!buffer) return buffer.error();
  buffer_ = std::move(*buffer);
  return processor_.process(buffer_, bias);
}

}  // namespace vts::renderer
