// A scene: the geometry the virtual texture is drawn on, seen by a camera. The virtual-texturing
// shader asks the scene one question per fragment — which finest-level texel (u, v) does this
// pixel see — and does the rest itself (level, page table, filtering). Each scene brings that
// answer twice: as GLSL for the GPU and in double precision for the CPU reference renderer, so
// the two can be compared pixel for pixel. Only the scene's own code is compiled into the shader
// variants, so a flat map builds no globe or lighting code.
//
// Precision contract: the GLSL never forms one float coordinate over the whole texture. It
// returns `rel`, the (u, v) offset from an integer anchor texel near what the camera looks at,
// which stays small wherever the camera is; the shader splits it into integer texel + fraction.
//
// Thread safety: scenes are values; const methods may be called from any thread.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

#include "vts/renderer/camera.hpp"

namespace vts::renderer {

using UvHit = std::optional<std::pair<double, double>>;

// Where a scene writes the uniforms its GLSL declares. The GL renderer passes one bound to a
// program (gl_uniforms.hpp); scenes themselves never call GL, so they work where there is no GL
// at all (the load test's demand simulator, headless builds).
class UniformSink {
 public:
  virtual ~UniformSink() = default;
  virtual void set(const char* name, float x) = 0;
  virtual void set(const char* name, float x, float y) = 0;
  virtual void set(const char* name, float x, float y, float z) = 0;
  virtual void set_int(const char* name, int x, int y) = 0;  // an ivec2
};

class Scene {
 public:
  virtual ~Scene() = default;
  // "plane", "globe": names the shader variant.
  virtual std::string_view name() const = 0;
  // GLSL placed after "#version 450 core" and before the virtual-texturing code. It declares its
  // own uniforms and defines
  //   bool scene_hit(vec2 px, out vec2 rel)
  // px: the fragment's position in pixels from the top-left of a viewport of u_viewport pixels
  // (declared by the caller as `uniform vec2 u_viewport;`); rel: (u, v) minus anchor(), in finest
  // texels; false for background. Derivatives of rel are taken by the caller after the call; a
  // scene whose u wraps (a globe's date line) sets u_period() so the caller unwraps them.
  virtual std::string glsl() const = 0;
  // Sets the uniforms glsl() declared, through `sink`, for the camera of a width x height view
  // (the feedback pass renders the same view with fewer pixels: it gets the full size).
  virtual void set_uniforms(UniformSink& sink, int width, int height) const = 0;
  // The integer finest texel rel is measured from.
  virtual std::array<std::int64_t, 2> anchor() const = 0;
  // The (u, v) the view is centred on: the page table's windows follow it.
  virtual std::pair<double, double> focus() const = 0;
  // Texels per pixel at the focus, for debug views (which level to show).
  virtual double texels_per_pixel() const = 0;
  // The CPU twin of scene_hit, in double precision and absolute: the (u, v) seen through point
  // (sx, sy) (pixels from the top-left; pixel centres at +0.5) of a width x height viewport.
  virtual UvHit hit(double sx, double sy, int width, int height) const = 0;
  // For a point where hit() misses: the (u, v) the GLSL scene_hit still writes to rel (absolute),
  // which the GPU's quad derivatives of a pixel next to the edge use; nullopt when the scene has no
  // meaningful value there (the CPU then takes a numeric derivative of the pixel itself).
  virtual UvHit miss_uv(double sx, double sy, int width, int height) const {
    (void)sx, (void)sy, (void)width, (void)height;
    return std::nullopt;
  }
  // The period of u when the surface wraps around (a globe: the image width), else 0.
  virtual double u_period() const { return 0; }
};

// The virtual texture on the plane w = 0, the camera of camera.hpp.
class PlaneScene final : public Scene {
 public:
  explicit PlaneScene(const PlaneView& view) : view_(view) {}
  const PlaneView& view() const { return view_; }

  std::string_view name() const override { return "plane"; }
  std::string glsl() const override;
  void set_uniforms(UniformSink& sink, int width, int height) const override;
  std::array<std::int64_t, 2> anchor() const override;
  std::pair<double, double> focus() const override { return {view_.center_u, view_.center_v}; }
  double texels_per_pixel() const override { return view_.texels_per_pixel; }
  UvHit hit(double sx, double sy, int width, int height) const override {
    return PlaneCamera::from_view(view_, width, height).hit(sx, sy);
  }

 private:
  PlaneView view_;
};

}  // namespace vts::renderer
