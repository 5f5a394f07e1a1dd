#include "vts/renderer/scene.hpp"

#include <algorithm>
#include <cmath>

#include "vts/renderer/shaders.hpp"

namespace vts::renderer {

namespace {
// Anchors stay inside the int range the shader uses, with room for the offsets it adds.
std::int64_t anchor_coord(double c) {
  return std::int64_t(std::clamp(std::floor(c), -1073741824.0, 1073741824.0));
}
}  // namespace

std::string PlaneScene::glsl() const {
  return detail::kPlaneScene;
}

std::array<std::int64_t, 2> PlaneScene::anchor() const {
  return {anchor_coord(view_.center_u), anchor_coord(view_.center_v)};
}

void PlaneScene::set_uniforms(UniformSink& sink, int width, int height) const {
  const PlaneCamera cam = PlaneCamera::from_view(view_, width, height);
  const auto a = anchor();
  // The only place the eye meets the anchor: in double, before anything becomes a float.
  const Vec3d eye_rel = cam.eye - Vec3d{double(a[0]), double(a[1]), 0};
  const auto set3 = [&sink](const char* name, Vec3d v) {
    sink.set(name, float(v.x), float(v.y), float(v.z));
  };
  set3("u_eye_rel", eye_rel);
  set3("u_forward", cam.forward);
  set3("u_right", cam.right);
  set3("u_up", cam.up);
  sink.set("u_tan_half_fov", float(cam.tan_half_fov));
  sink.set("u_aspect", float(cam.aspect));
}

}  // namespace vts::renderer
