// A camera path: keyframes at frame numbers, interpolated between them, for scripted flights of
// `vts view` (benchmarks, screenshots, regression runs).
//
// JSON form (one of the two key kinds per path; a key may also carry both):
//   {"keys": [{"frame": 0, "center": [u, v], "texels_per_pixel": 4, "heading": 0, "tilt": 0},
//             ...]}                                                                 plane keys
//   {"keys": [{"frame": 0, "lon": 0, "lat": 20, "altitude_m": 2e7, "heading": 0, "tilt": 0},
//             ...]}                                                                 globe keys
// Angles are radians. A field left out of a key keeps the previous key's value (the first key's
// defaults are parse()'s `defaults`). Frames must be finite and strictly increasing.
//
// Interpolation: linear in the frame number for positions and angles, in log space for the zoom
// (texels_per_pixel) and the altitude, so a zoom-in moves at a steady pace on screen. Outside the
// keys' frame range the path holds the first or last key.
//
// Thread safety: a CameraPath is a value; const methods may be called from any thread.
#pragma once

#include <string_view>
#include <vector>

#include "vts/protocol/result.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/globe.hpp"

namespace vts::renderer {

struct CameraKey {
  double t = 0;  // the frame number
  PlaneView plane;
  GlobeView globe;
};

class CameraPath {
 public:
  // invalid_argument naming the key (by index) and the field that is wrong: not JSON, no "keys"
  // array, an empty one, a field of the wrong type, a non-positive zoom or altitude, frames not
  // strictly increasing. `defaults` fills in what the first key leaves out (its t is ignored).
  static Result<CameraPath> parse(std::string_view json_text, const CameraKey& defaults = {});
  // The keys must be non-empty and sorted by strictly increasing t (not checked here).
  explicit CameraPath(std::vector<CameraKey> keys) : keys_(std::move(keys)) {}

  const std::vector<CameraKey>& keys() const { return keys_; }
  bool has_plane() const { return has_plane_; }  // some key set a plane field
  bool has_globe() const { return has_globe_; }  // some key set a globe field
  double first_frame() const { return keys_.empty() ? 0 : keys_.front().t; }
  double last_frame() const { return keys_.empty() ? 0 : keys_.back().t; }

  PlaneView plane_at(double frame) const;
  GlobeView globe_at(double frame) const;

 private:
  CameraPath() = default;
  std::vector<CameraKey> keys_;
  bool has_plane_ = false, has_globe_ = false;
};

}  // namespace vts::renderer
