// The globe scene: the virtual texture as an equirectangular image wrapped on a sphere of the
// Earth's radius, seen from a camera placed by longitude, latitude and altitude.
//
// Mapping: the image's W x H finest texels cover longitude [-180, 180) left to right and latitude
// [90, -90] top to bottom: u = (lon + 180) / 360 * W, v = (90 - lat) / 180 * H. u wraps with
// period W (u_period()), so derivatives across the date line are unwrapped.
//
// Precision (docs/RENDERER.md, "Precision"): everything that involves the sphere's radius is done
// on the CPU in double and reaches the GPU relative to the eye or to the anchor, so a camera 1 m
// above the surface neither jitters nor loses texels.
#pragma once

#include <cstdint>
#include <memory>

#include "vts/renderer/scene.hpp"

namespace vts::renderer {

// GlobeScene::texels_per_pixel() has no viewport: it is given for a viewport of this many rows.
inline constexpr double kGlobeNominalHeightPx = 1024;

inline constexpr double kEarthRadiusM = 6371008.8;  // mean Earth radius (IUGG)

struct GlobeView {
  double lon_deg = 0, lat_deg = 0;  // the camera's nadir
  double altitude_m = 2e7;          // above the sphere (> 0)
  double heading = 0;               // radians: where screen-up points; 0 = north, pi/2 = east
  double tilt = 0;                  // radians: 0 looks straight down, towards pi/2 at the horizon
  double fov_y = 0.8;               // vertical field of view, radians
  double radius_m = kEarthRadiusM;
  friend bool operator==(const GlobeView&, const GlobeView&) = default;
};

class GlobeScene final : public Scene {
 public:
  // image_width x image_height: the finest level's size (Geometry::width/height).
  GlobeScene(const GlobeView& view, std::uint64_t image_width, std::uint64_t image_height);
  const GlobeView& view() const { return view_; }

  std::string_view name() const override { return "globe"; }
  std::string glsl() const override;
  void set_uniforms(UniformSink& sink, int width, int height) const override;
  std::array<std::int64_t, 2> anchor() const override;
  std::pair<double, double> focus() const override;
  // For a 1024-row viewport (the interface has no viewport): the pixel's angular size there, times
  // the distance to the focus, times W / (2 pi R).
  double texels_per_pixel() const override;
  UvHit hit(double sx, double sy, int width, int height) const override;
  // Past the limb, the point the ray's parameter s = c / (-b + sqrt(max(disc, 0))) reaches (the
  // eye's nadir when the ray points away), as scene_hit computes it.
  UvHit miss_uv(double sx, double sy, int width, int height) const override;
  double u_period() const override { return double(width_); }

 private:
  struct Camera;  // the view's camera basis, worked out once (globe.cpp)
  GlobeView view_;
  std::uint64_t width_ = 1, height_ = 1;
  std::shared_ptr<const Camera> camera_;
};

}  // namespace vts::renderer
