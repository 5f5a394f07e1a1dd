// The viewer's CPU side: its default camera, --scene specs, the camera the mouse and keys move,
// the recorder of every frame's camera, and the HUD's text. No GL, no window: events arrive as
// plain values, so all of it runs in unit tests.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/camera_path.hpp"
#include "vts/renderer/globe.hpp"

namespace vts::renderer {

// The default views: the whole image in a width x height frame (plane), the Earth from
// 20 000 km (globe).
CameraKey default_camera(const Geometry& geometry, int width, int height);

// --scene: "plane", "globe" or a JSON file {"scene": "plane"|"globe", "camera": {view fields}}.
// Sets `globe`, and `camera` from the file's camera (other fields kept). invalid_argument naming
// `spec` and the problem.
Status parse_scene(const std::string& spec, bool& globe, CameraKey& camera);

// The numbers the HUD shows. uploads and frame_ms are per-frame averages; debug is the debug
// view's name, empty for none.
struct HudNumbers {
  std::uint32_t resident = 0, pending = 0;
  double uploads = 0, frame_ms = 0, hit_ratio = 0, mip_bias = 0;
  std::string debug;
  bool bc1 = false;
  std::uint64_t physical_bytes = 0, page_table_bytes = 0;
  // Georeferenced tilesets: the place at the plane's screen centre (lonlat_text(), geo_view.hpp);
  // empty otherwise. The plane's camera line ends with it.
  std::string place;
};

// Four lines: streaming numbers, hit ratio / bias / frame time, the physical texture, then the
// camera (the globe's or the plane's).
std::vector<std::string> hud_lines(const HudNumbers& n, bool globe, const PlaneView& plane,
                                   const GlobeView& globe_view);

// The HUD's glyph scale for a frame `framebuffer_height` pixels tall: an integer (1 below 720
// rows, 2 from 720, 3 from 1080, ...) so glyph edges stay on pixel edges.
float hud_scale(int framebuffer_height);

// The interactive camera. Coordinates are window coordinates; `scale` converts them to
// framebuffer pixels; fb_width x fb_height is the framebuffer's size.
//   left drag: pan (plane: the texel under the cursor stays under it) / orbit (globe);
//   right drag, Q/E, R/F: heading, tilt (tilt in [0, 1.4]);
//   scroll: zoom about the cursor (plane) / altitude (globe); 1-4: debug views; H: the HUD.
// Any camera move sets touched() (a followed camera path stops driving the camera).
class CameraControls {
 public:
  enum class Button { left, right, other };
  enum class Key { one, two, three, four, h, q, e, r, f, other };

  CameraControls(bool globe, const CameraKey& start, std::uint64_t image_width,
                 std::uint64_t image_height);

  bool cursor_seen() const { return cursor_seen_; }
  // Where the cursor is in framebuffer pixels (the last cursor event's place times its scale);
  // nullopt before the first cursor event.
  std::optional<std::pair<double, double>> cursor_pixel() const;
  // (x, y): where the cursor is, used only when no cursor event was seen yet.
  void button(Button b, bool down, double x, double y);
  void cursor(double x, double y, double scale, int fb_width, int fb_height);
  // (x, y): as for button(); the zoom keeps the texel under the cursor (plane).
  void scroll(double yoffset, double x, double y, double scale, int fb_width, int fb_height);
  // repeat: a held key's repeat (H toggles on a press only).
  void key(Key k, bool repeat);

  bool globe() const { return globe_; }
  PlaneView plane;
  GlobeView globe_view;
  bool touched = false;
  bool show_hud = true;
  // A debug view asked for with 1-4 (0 none .. 3 page table), for the owner to apply and reset.
  std::optional<int> debug_request;

 private:
  void drag(double dx, double dy, double px, double py, int fb_width, int fb_height);

  bool globe_;
  std::uint64_t image_w_, image_h_;
  bool left_ = false, right_ = false;
  // The cursor as the latest event placed it. Events are handled in order, so a press and the
  // moves after it, read in one batch, still see the press's place.
  double last_x_ = 0, last_y_ = 0, scale_ = 1;
  bool cursor_seen_ = false;
};

// The camera of every rendered frame (frames from 0), kept as keys where it changes. A camera
// that holds still for frames i..j and then changes at j + 1 gets keys at i and j, so linear
// interpolation replays every recorded frame exactly. Keys marked `move` stay moves.
class CameraRecorder {
 public:
  explicit CameraRecorder(bool globe) : globe_(globe) {}
  void add(double frame, const PlaneView& plane, const GlobeView& globe, bool move);
  bool empty() const { return keys_.empty(); }
  // The path so far, with a key at the last frame; only the scene's own kind of fields.
  CameraPath path() const;

 private:
  bool same(const CameraKey& a, const CameraKey& b) const;

  bool globe_;
  std::vector<CameraKey> keys_;
  CameraKey last_;
};

}  // namespace vts::renderer
