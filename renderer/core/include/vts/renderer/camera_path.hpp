// A camera path: keyframes at frame numbers, interpolated between them, for scripted flights of
// `vts view` (benchmarks, screenshots, regression runs, `--record`) and for the load test's
// simulated viewers (built-in presets, preset()).
//
// JSON form (one of the two key kinds per path; a key may also carry both):
//   {"keys": [{"frame": 0, "center": [u, v], "texels_per_pixel": 4, "heading": 0, "tilt": 0},
//             ...]}                                                                 plane keys
//   {"keys": [{"frame": 0, "lon": 0, "lat": 20, "altitude_m": 2e7, "heading": 0, "tilt": 0},
//             ...]}                                                                 globe keys
// Angles are radians (lon and lat: degrees). A field left out of a key keeps the previous key's
// value (the first key's defaults are parse()'s `defaults`). Frames must be finite and strictly
// increasing; they need not be integers. Optional per key, and not carried over: "move": true
// marks a key where the camera starts a new view (a jump lands there), so a load test can measure
// the time to full resolution from it. The first key is always a move.
//
// Interpolation: linear in the frame number for positions and angles, in log space for the zoom
// (texels_per_pixel) and the altitude, so a zoom-in moves at a steady pace on screen. Longitude is
// interpolated linearly too (not the short way round): a path that crosses the date line gives
// unwrapped longitudes (179, 181, ...), which name the same places as (179, -179, ...). Outside
// the keys' frame range the path holds the first or last key.
//
// Thread safety: a CameraPath is a value; const methods may be called from any thread.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/globe.hpp"

namespace vts::renderer {

struct CameraKey {
  double t = 0;  // the frame number
  PlaneView plane;
  GlobeView globe;
  bool move = false;  // the camera starts a new view here ("move": true); the first key always is
};

// What a built-in path needs to know. Frames are the path's time unit: frame n is at n / fps
// seconds, and a preset's keys cover frames [0, ceil(duration_s * fps)].
struct PresetOptions {
  std::uint64_t image_width = 0, image_height = 0;  // the finest level's size (Geometry)
  double fps = 60;                                  // frames per second, (0, 1000]
  double duration_s = 60;                           // (0, 86400]
  std::uint64_t seed = 0;  // places, directions; one per simulated viewer, so they differ
  int viewport_width = 1280, viewport_height = 720;  // pixels, [1, 16384]: picks the zooms
  double dwell_s = 2;  // "jumps": how long each place is held; at least 2 frames
};

class CameraPath {
 public:
  // invalid_argument naming the key (by index) and the field that is wrong: not JSON, no "keys"
  // array, an empty one, a field of the wrong type, a non-positive zoom or altitude, frames not
  // strictly increasing. `defaults` fills in what the first key leaves out (its t is ignored).
  // The first key's `move` is set.
  static Result<CameraPath> parse(std::string_view json_text, const CameraKey& defaults = {});

  // A built-in path (docs/RENDERER.md, "Camera paths"), deterministic for its options:
  //   "flyover"  globe; constant altitude showing about 1.5 finest texels per pixel at the screen
  //              centre, which sees the ground 0.3 rad off the vertical (tilt 0.3 when low),
  //              flying east-ish at half a screen height per second, the heading along the
  //              motion, the latitude swinging gently (at most 10 degrees either side of its mean,
  //              every 30 s); start from the seed.
  //   "zoom"     globe; from orbit (2e7 m, the whole planet; higher when the image is so coarse
  //              that its finest level shows from there) straight down to the finest altitude
  //              (tilt 0), log-linear over the duration, above a place chosen by the seed.
  //   "jumps"    globe; seeded random places at the finest altitude (tilt 0), each held for
  //              dwell_s (keys at its first and last frame), then a one-frame jump: keys f and
  //              f + 1 at different places, the landing key marked `move`.
  //   "pan"      plane; 1 texel per pixel, heading and tilt 0, the centre moving at half a screen
  //              width per second (at most the inner image's width or height per second) in a
  //              seeded direction, bouncing off the image's edges (kept half a screen inside them,
  //              or in the image's middle half when it is smaller), from a seeded start; keys at
  //              the start, every bounce (fractional frames) and the end.
  // invalid_argument naming the problem: an unknown name (the known ones listed), an empty
  // image, an fps, duration, viewport or dwell out of range.
  static Result<CameraPath> preset(std::string_view name, const PresetOptions& options);
  // The names preset() knows, in the order above.
  static std::vector<std::string_view> preset_names();

  // The keys must be non-empty and sorted by strictly increasing t (not checked here).
  // has_plane() and has_globe() are as given (both false: to_json() writes both kinds).
  explicit CameraPath(std::vector<CameraKey> keys, bool has_plane = false, bool has_globe = false)
      : keys_(std::move(keys)), has_plane_(has_plane), has_globe_(has_globe) {}

  const std::vector<CameraKey>& keys() const { return keys_; }
  bool has_plane() const { return has_plane_; }  // some key set a plane field
  bool has_globe() const { return has_globe_; }  // some key set a globe field
  double first_frame() const { return keys_.empty() ? 0 : keys_.front().t; }
  double last_frame() const { return keys_.empty() ? 0 : keys_.back().t; }
  // The frames of the keys marked `move` (the first key's always), increasing.
  std::vector<double> move_frames() const;

  PlaneView plane_at(double frame) const;
  GlobeView globe_at(double frame) const;

  // The JSON form above, one key per line: every key with its frame, the plane fields when
  // has_plane(), the globe fields when has_globe() (both when neither), heading, tilt and fov_y
  // (the globe view's for a globe-only path, else the plane view's), and "move": true on the first
  // key and on moves. Numbers are printed so that they read back bit for bit: parse(to_json())
  // gives the same keys (fields of a kind not written come from parse()'s defaults).
  std::string to_json() const;

 private:
  CameraPath() = default;
  std::vector<CameraKey> keys_;
  bool has_plane_ = false, has_globe_ = false;
};

}  // namespace vts::renderer
