// vts view: the sparse-virtual-texture viewer. Thin glue over the libraries: a source (any
// location open_source accepts) -> TileClient (RAM cache, optional disk cache, decode pool) ->
// VirtualTexture -> a plane or globe scene, driven by the mouse, a camera path, or nothing.
//
// Interactive (default): a visible window with the HUD (resident, pending, uploads per frame, hit
// ratio, mip bias, frame time, camera) drawn in its top-left corner (key H hides it); the title
// and stderr carry the same numbers.
// Headless (--headless --frames N): a hidden window renders N frames (optionally stopping at the
// first complete one), writes the last as a PNG and prints per-frame stats (JSON with --json).
// Screenshots are the virtual texture's frame alone, comparable with the reference renderer,
// unless --hud asks for the HUD in them too.
// --print-camera prints the final camera as a one-key camera path: "record a view" for
// --camera-path to replay. --record FILE writes the whole flight as a camera path on exit (a key
// for every frame whose camera changed), which --camera-path replays frame for frame.
#include <GLFW/glfw3.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "vts/client/saved_source.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/renderer/camera.hpp"
#include "vts/renderer/camera_path.hpp"
#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/globe.hpp"
#include "vts/renderer/hud.hpp"
#include "vts/renderer/reference.hpp"
#include "vts/renderer/scene.hpp"
#include "vts/renderer/virtual_texture.hpp"

namespace vts::cli {

namespace {

using Clock = std::chrono::steady_clock;
using namespace vts::renderer;

struct ViewArgs {
  std::string source, cache_dir, scene = "plane", camera_path, debug = "none", screenshot, record;
  std::uint64_t ram_mb = 256;
  int width = 1280, height = 720;
  std::uint32_t slots = 256, window = 64, upload_tiles = 32;
  int feedback = 8, anisotropy = 8;
  bool headless = false, json = false, until_complete = false, hud = false, print_camera = false;
  int frames = 0;
};

DebugView debug_from_name(const std::string& s) {
  if (s == "levels") return DebugView::levels;
  if (s == "physical") return DebugView::physical;
  if (s == "page-table") return DebugView::page_table;
  return DebugView::none;
}

const char* debug_name(DebugView v) {
  switch (v) {
    case DebugView::levels:
      return "levels";
    case DebugView::physical:
      return "physical";
    case DebugView::page_table:
      return "page-table";
    case DebugView::none:
      break;
  }
  return "none";
}

Result<std::string> read_text(const std::string& path, const char* what) {
  std::ifstream in(path, std::ios::binary);
  if (!in)
    return make_error(ErrorCode::not_found, std::string(what) + " " + path + ": cannot be read");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// The default views: the whole image in the window (plane), the Earth from 20 000 km (globe).
CameraKey default_camera(const Geometry& g, int width, int height) {
  CameraKey k;
  k.plane.center_u = double(g.width()) / 2;
  k.plane.center_v = double(g.height()) / 2;
  k.plane.texels_per_pixel =
      std::max(double(g.width()) / width, double(g.height()) / height) * 1.05;
  k.globe.lon_deg = 0;
  k.globe.lat_deg = 20;
  k.globe.altitude_m = 2e7;
  return k;
}

// --scene: "plane", "globe" or a JSON file {"scene": "plane"|"globe", "camera": {view fields}}.
// Sets `globe` and overrides `camera` with the file's camera.
Status parse_scene(const std::string& spec, bool& globe, CameraKey& camera) {
  if (spec == "plane" || spec == "globe") {
    globe = spec == "globe";
    return {};
  }
  auto text = read_text(spec, "--scene file");
  if (!text) {
    return make_error(ErrorCode::invalid_argument,
                      "--scene '" + spec + "' is neither plane, globe nor a readable JSON file");
  }
  auto doc = nlohmann::json::parse(*text, nullptr, false);
  auto bad = [&](const std::string& why) {
    return make_error(ErrorCode::invalid_argument, "--scene " + spec + ": " + why);
  };
  if (doc.is_discarded() || !doc.is_object()) return bad("not a JSON object");
  auto s = doc.find("scene");
  if (s == doc.end() || !s->is_string() || (*s != "plane" && *s != "globe"))
    return bad("\"scene\" must be \"plane\" or \"globe\"");
  globe = *s == "globe";
  if (auto c = doc.find("camera"); c != doc.end()) {
    if (!c->is_object()) return bad("\"camera\" is not a JSON object");
    nlohmann::json key = *c;
    key["frame"] = 0;
    auto path = CameraPath::parse(nlohmann::json{{"keys", {key}}}.dump(), camera);
    if (!path) {
      std::string msg = path.error().message;
      const std::string prefix = "camera path: key 0: ";
      if (msg.rfind(prefix, 0) == 0) msg = msg.substr(prefix.size());
      return bad("\"camera\": " + msg);
    }
    camera = path->keys().front();
  }
  return {};
}

nlohmann::json stats_json(const FrameStats& s) {
  return {{"frame", s.frame},
          {"vt_cpu_ms", s.vt_cpu_ms},
          {"frame_ms", s.frame_ms},
          {"wanted", s.wanted},
          {"wanted_missing", s.wanted_missing},
          {"resident", s.resident},
          {"pending", s.pending},
          {"uploads", s.uploads},
          {"upload_bytes", s.upload_bytes},
          {"feedback_frames", s.feedback_frames},
          {"mip_bias", s.mip_bias},
          {"hit_ratio", s.hit_ratio},
          {"evictions", s.evictions},
          {"refusals", s.refusals},
          {"absent", s.absent},
          {"errors", s.errors},
          {"complete", s.complete}};
}

// The camera as a one-key camera path (camera_path.hpp) that --camera-path replays: the fields of
// the scene's own view; "scene" and "debug" say what else was on screen (CameraPath ignores them).
nlohmann::json camera_json(bool globe, const PlaneView& p, const GlobeView& g, DebugView debug) {
  nlohmann::json key = {{"frame", 0}};
  if (globe) {
    key["lon"] = g.lon_deg;
    key["lat"] = g.lat_deg;
    key["altitude_m"] = g.altitude_m;
    key["heading"] = g.heading;
    key["tilt"] = g.tilt;
    key["fov_y"] = g.fov_y;
  } else {
    key["center"] = {p.center_u, p.center_v};
    key["texels_per_pixel"] = p.texels_per_pixel;
    key["heading"] = p.heading;
    key["tilt"] = p.tilt;
    key["fov_y"] = p.fov_y;
  }
  return {{"scene", globe ? "globe" : "plane"}, {"debug", debug_name(debug)}, {"keys", {key}}};
}

// --record: the camera of every rendered frame (frames counted from 0), kept as keys where it
// changes. A camera that holds still for frames i..j and then changes at j + 1 gets keys at i and j
// (linear interpolation would otherwise glide from i to j + 1), so the path replays the camera of
// every recorded frame exactly. Keys the followed camera path marks as moves stay moves.
class Recorder {
 public:
  explicit Recorder(bool globe) : globe_(globe) {}

  void add(double frame, const PlaneView& plane, const GlobeView& globe, bool move) {
    CameraKey k;
    k.t = frame;
    k.plane = plane;
    k.globe = globe;
    k.move = move || keys_.empty();
    if (keys_.empty()) {
      keys_.push_back(k);
    } else if (k.move || !same(k, last_)) {
      if (keys_.back().t < last_.t) keys_.push_back(last_);  // the end of a still stretch
      keys_.push_back(k);
    }
    last_ = k;
    last_.move = false;
  }
  bool empty() const { return keys_.empty(); }

  // The path so far, with a key at the last frame; only the scene's own kind of fields.
  CameraPath path() const {
    std::vector<CameraKey> keys = keys_;
    if (!keys.empty() && keys.back().t < last_.t) keys.push_back(last_);
    return CameraPath(std::move(keys), !globe_, globe_);
  }

 private:
  bool same(const CameraKey& a, const CameraKey& b) const {
    if (globe_) {
      const GlobeView &x = a.globe, &y = b.globe;
      return x.lon_deg == y.lon_deg && x.lat_deg == y.lat_deg && x.altitude_m == y.altitude_m &&
             x.heading == y.heading && x.tilt == y.tilt && x.fov_y == y.fov_y;
    }
    const PlaneView &x = a.plane, &y = b.plane;
    return x.center_u == y.center_u && x.center_v == y.center_v &&
           x.texels_per_pixel == y.texels_per_pixel && x.heading == y.heading && x.tilt == y.tilt &&
           x.fov_y == y.fov_y;
  }

  bool globe_;
  std::vector<CameraKey> keys_;
  CameraKey last_;
};

// Writes `text` to `path` through a temporary file in the same folder and a rename, so the file
// is either the old one or the whole new one.
Status write_atomically(const std::string& path, const std::string& text) {
  namespace fs = std::filesystem;
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  std::error_code ec;
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(text.data(), std::streamsize(text.size()));
    out.flush();
    if (!out) {
      fs::remove(tmp, ec);
      return make_error(ErrorCode::io, "--record: cannot write " + tmp);
    }
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    return make_error(ErrorCode::io,
                      "--record: cannot rename " + tmp + " to " + path + ": " + ec.message());
  }
  return {};
}

// The HUD's text: streaming numbers, the physical texture, then the camera. uploads and ms are
// per-frame averages.
std::vector<std::string> hud_lines(const FrameStats& st, double uploads, double ms,
                                   const VirtualTexture& vt, bool globe, const PlaneView& p,
                                   const GlobeView& g) {
  const DebugView debug = vt.debug_view();
  char buf[4][160];
  std::snprintf(buf[0], sizeof buf[0], "resident %u  pending %u  uploads %.1f/frame", st.resident,
                st.pending, uploads);
  std::snprintf(buf[1], sizeof buf[1], "hit %.1f%%  bias %.2f  %.1f ms/frame%s%s",
                st.hit_ratio * 100, st.mip_bias, ms, debug == DebugView::none ? "" : "  debug ",
                debug == DebugView::none ? "" : debug_name(debug));
  if (globe) {
    std::snprintf(buf[2], sizeof buf[2], "lon %.4f  lat %.4f  altitude %.0f m", g.lon_deg,
                  g.lat_deg, g.altitude_m);
  } else {
    std::snprintf(buf[2], sizeof buf[2], "center %.1f, %.1f  %.3g texels/pixel", p.center_u,
                  p.center_v, p.texels_per_pixel);
  }
  const bool bc1 = vt.tile_format() == PixelFormat::bc1;
  std::snprintf(buf[3], sizeof buf[3], "%s slots  physical %.1f MiB  page table %.2f MiB",
                bc1 ? "bc1 (S3TC)" : "rgba8", double(vt.physical_gpu_bytes()) / (1 << 20),
                double(vt.page_table_gpu_bytes()) / (1 << 20));
  return {buf[0], buf[1], buf[3], buf[2]};
}

// Integer glyph scales keep the HUD's edges on pixel edges: 1 below 720 rows, 2 from 720, 3 from
// 1080, ... (stb_easy_font's glyphs are 9 pixels tall at scale 1).
float hud_scale(int framebuffer_height) {
  return std::max(1.0f, std::floor(float(framebuffer_height) / 360.0f));
}

// The interactive camera: what the mouse and keys change.
struct Controls {
  bool globe = false;
  PlaneView plane;
  GlobeView globe_view;
  std::uint64_t image_w = 1, image_h = 1;
  bool left = false, right = false;
  // The cursor as the latest event placed it, in window coordinates. Events are handled in
  // order, so a press and the moves after it, read in one batch, still see the press's place
  // (asking the server instead would give the place after the whole batch).
  double last_x = 0, last_y = 0;
  bool cursor_seen = false;
  bool touched = false;  // the user moved the camera (a camera path stops driving it)
  bool show_hud = true;
  std::optional<DebugView> debug_request;

  // Window coordinates -> framebuffer pixels.
  double scale(GLFWwindow* w) const {
    int ww = 0, wh = 0, fw = 0, fh = 0;
    glfwGetWindowSize(w, &ww, &wh);
    glfwGetFramebufferSize(w, &fw, &fh);
    return ww > 0 ? double(fw) / ww : 1.0;
  }
  void fb_size(GLFWwindow* w, int& fw, int& fh) const { glfwGetFramebufferSize(w, &fw, &fh); }
};

Controls* controls_of(GLFWwindow* w) {
  return static_cast<Controls*>(glfwGetWindowUserPointer(w));
}

void on_mouse_button(GLFWwindow* w, int button, int action, int) {
  Controls& c = *controls_of(w);
  const bool down = action == GLFW_PRESS;
  if (button == GLFW_MOUSE_BUTTON_LEFT) c.left = down;
  if (button == GLFW_MOUSE_BUTTON_RIGHT) c.right = down;
  if (!c.cursor_seen) {
    glfwGetCursorPos(w, &c.last_x, &c.last_y);
    c.cursor_seen = true;
  }
}

void on_cursor(GLFWwindow* w, double x, double y) {
  Controls& c = *controls_of(w);
  const double k = c.scale(w);
  const double dx = (x - c.last_x) * k, dy = (y - c.last_y) * k;
  const double px = c.last_x * k, py = c.last_y * k;
  c.last_x = x;
  c.last_y = y;
  const bool first = !c.cursor_seen;
  c.cursor_seen = true;
  if (first || (!c.left && !c.right)) return;
  c.touched = true;
  int fw = 1, fh = 1;
  c.fb_size(w, fw, fh);
  fh = std::max(fh, 1);
  if (c.globe) {
    GlobeView& g = c.globe_view;
    if (c.left) {
      // Degrees per pixel near the nadir: the ground a pixel covers at this altitude.
      const double deg =
          g.altitude_m * 2 * std::tan(g.fov_y / 2) / fh / g.radius_m * 180 / std::numbers::pi;
      const double ch = std::cos(g.heading), sh = std::sin(g.heading);
      // Screen right/up rotated by the heading into east/north.
      const double east = -(dx * ch + dy * sh) * deg, north = (dy * ch - dx * sh) * deg;
      g.lon_deg = std::remainder(
          g.lon_deg + east / std::max(std::cos(g.lat_deg * std::numbers::pi / 180), 0.05), 360.0);
      g.lat_deg = std::clamp(g.lat_deg + north, -89.0, 89.0);
    } else {
      g.heading += dx * 0.005;
      g.tilt = std::clamp(g.tilt + dy * 0.005, 0.0, 1.4);
    }
    return;
  }
  PlaneView& v = c.plane;
  if (c.left) {
    // Keep the texel under the cursor under the cursor.
    const PlaneCamera cam = PlaneCamera::from_view(v, fw, fh);
    auto a = cam.hit(px, py), b = cam.hit(px + dx, py + dy);
    if (a && b) {
      v.center_u += a->first - b->first;
      v.center_v += a->second - b->second;
    } else {
      const double ch = std::cos(v.heading), sh = std::sin(v.heading);
      v.center_u -= (dx * ch - dy * sh) * v.texels_per_pixel;
      v.center_v -= (dx * sh + dy * ch) * v.texels_per_pixel;
    }
  } else {
    v.heading += dx * 0.005;
    v.tilt = std::clamp(v.tilt + dy * 0.005, 0.0, 1.4);
  }
}

void on_scroll(GLFWwindow* w, double, double yoff) {
  Controls& c = *controls_of(w);
  c.touched = true;
  const double f = std::pow(1.25, -yoff);  // scroll up: closer
  if (c.globe) {
    c.globe_view.altitude_m = std::clamp(c.globe_view.altitude_m * f, 1.0, 1e9);
    return;
  }
  int fw = 1, fh = 1;
  c.fb_size(w, fw, fh);
  double x = c.last_x, y = c.last_y;
  if (!c.cursor_seen) glfwGetCursorPos(w, &x, &y);
  const double k = c.scale(w);
  PlaneView& v = c.plane;
  const auto before = PlaneCamera::from_view(v, fw, std::max(fh, 1)).hit(x * k, y * k);
  const double max_tpp = 4.0 * double(std::max(c.image_w, c.image_h));
  v.texels_per_pixel = std::clamp(v.texels_per_pixel * f, 1.0 / 64, max_tpp);
  const auto after = PlaneCamera::from_view(v, fw, std::max(fh, 1)).hit(x * k, y * k);
  if (before && after) {
    v.center_u += before->first - after->first;
    v.center_v += before->second - after->second;
  }
}

void on_key(GLFWwindow* w, int key, int, int action, int) {
  if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
  Controls& c = *controls_of(w);
  double& heading = c.globe ? c.globe_view.heading : c.plane.heading;
  double& tilt = c.globe ? c.globe_view.tilt : c.plane.tilt;
  switch (key) {
    case GLFW_KEY_ESCAPE:
      glfwSetWindowShouldClose(w, GLFW_TRUE);
      break;
    case GLFW_KEY_1:
      c.debug_request = DebugView::none;
      break;
    case GLFW_KEY_2:
      c.debug_request = DebugView::levels;
      break;
    case GLFW_KEY_3:
      c.debug_request = DebugView::physical;
      break;
    case GLFW_KEY_4:
      c.debug_request = DebugView::page_table;
      break;
    case GLFW_KEY_H:
      if (action == GLFW_PRESS) c.show_hud = !c.show_hud;
      break;
    case GLFW_KEY_Q:
      heading -= 0.05;
      c.touched = true;
      break;
    case GLFW_KEY_E:
      heading += 0.05;
      c.touched = true;
      break;
    case GLFW_KEY_R:
      tilt = std::clamp(tilt + 0.05, 0.0, 1.4);
      c.touched = true;
      break;
    case GLFW_KEY_F:
      tilt = std::clamp(tilt - 0.05, 0.0, 1.4);
      c.touched = true;
      break;
    default:
      break;
  }
}

int run_view(const ViewArgs& a) {
  // Options first: nothing opens before they are known to be good.
  if (a.width < 1 || a.height < 1 || a.width > 16384 || a.height > 16384)
    return report_error(
        make_error(ErrorCode::invalid_argument, "--width/--height must be between 1 and 16384"));
  if (a.headless && a.frames < 1)
    return report_error(
        make_error(ErrorCode::invalid_argument, "--headless needs --frames N (N >= 1)"));
  std::optional<std::string> path_text;
  if (!a.camera_path.empty()) {
    auto t = read_text(a.camera_path, "--camera-path");
    if (!t) return report_error(t.error());
    path_text = std::move(*t);
  }
  if (!a.record.empty()) {
    // Known before a long session, not at its end: the folder the file goes to exists.
    namespace fs = std::filesystem;
    const fs::path dir = fs::path(a.record).parent_path();
    std::error_code ec;
    if (fs::is_directory(a.record, ec) || !fs::is_directory(dir.empty() ? "." : dir, ec))
      return report_error(
          make_error(ErrorCode::invalid_argument,
                     "--record " + a.record + ": not a file in an existing folder"));
  }

  // The source, the tile client with its caches.
  client::SourceOptions so;
  auto opened = client::open_source(a.source, so);
  if (!opened && opened.error().code == ErrorCode::io && !a.cache_dir.empty()) {
    // Offline: a cache that saw this source before still knows the tileset.
    if (auto saved = client::load_source_info(a.cache_dir, a.source)) {
      std::fprintf(stderr, "vts view: %s: %s; showing what the cache holds\n", a.source.c_str(),
                   opened.error().message.c_str());
      opened = client::offline_source(std::move(*saved));
    }
  }
  if (!opened) return report_error(opened.error());
  std::shared_ptr<client::TileSource> source = std::move(*opened);
  const Geometry geometry = source->info().info.geometry;

  CameraKey camera = default_camera(geometry, a.width, a.height);
  bool globe = false;
  if (auto s = parse_scene(a.scene, globe, camera); !s) return report_error(s.error());
  std::optional<CameraPath> path;
  if (path_text) {
    auto p = CameraPath::parse(*path_text, camera);
    if (!p)
      return report_error(make_error(p.error().code, a.camera_path + ": " + p.error().message));
    path = std::move(*p);
    if (globe ? !path->has_globe() && path->has_plane() : !path->has_plane() && path->has_globe())
      std::fprintf(stderr,
                   "vts view: warning: %s has only %s fields; the %s camera stays where it is\n",
                   a.camera_path.c_str(), globe ? "plane" : "globe", globe ? "globe" : "plane");
  }

  client::TileClientOptions co;
  co.cache.ram_bytes = std::size_t(a.ram_mb) << 20;
  if (!a.cache_dir.empty()) {
    co.cache.disk = client::DiskCacheOptions{};
    co.cache.disk->dir = a.cache_dir;
  }
  auto created = client::TileClient::create(source, co);
  if (!created) return report_error(created.error());
  std::shared_ptr<client::TileClient> tiles = std::move(*created);
  if (!a.cache_dir.empty() && !source->local())
    if (auto saved = client::save_source_info(a.cache_dir, a.source, source->info()); !saved)
      std::fprintf(stderr, "vts view: warning: %s\n", saved.error().message.c_str());

  // The window and the virtual texture.
  GlContextOptions go;
  go.width = a.width;
  go.height = a.height;
  go.visible = !a.headless;
  go.vsync = !a.headless;
  go.title = "vts view " + a.source;
  auto gl_made = GlContext::create(go);
  if (!gl_made) return report_error(gl_made.error());
  std::unique_ptr<GlContext> gl = std::move(*gl_made);

  VirtualTextureOptions vo;
  vo.slots = a.slots;
  vo.window = a.window;
  vo.feedback_divisor = a.feedback;
  vo.upload_tiles = a.upload_tiles;
  vo.anisotropy = a.anisotropy;
  vo.debug = debug_from_name(a.debug);
  auto vt_made = VirtualTexture::create(tiles, geometry, vo);
  if (!vt_made) return report_error(vt_made.error());
  std::unique_ptr<VirtualTexture> vt = std::move(*vt_made);

  Controls ctl;
  ctl.globe = globe;
  ctl.plane = camera.plane;
  ctl.globe_view = camera.globe;
  ctl.image_w = geometry.width();
  ctl.image_h = geometry.height();

  // The frames a followed camera path starts a new view at (--record keeps them as moves).
  std::vector<double> path_moves;
  if (path) path_moves = path->move_frames();
  std::optional<Recorder> recorder;
  if (!a.record.empty()) recorder.emplace(globe);

  // One frame of the current camera at w x h.
  auto render = [&](double frame, int w, int h, bool follow_path) {
    bool move = false;
    if (path && follow_path) {
      ctl.plane = path->plane_at(frame);
      ctl.globe_view = path->globe_at(frame);
      move = std::binary_search(path_moves.begin(), path_moves.end(), frame);
    }
    if (recorder) recorder->add(frame, ctl.plane, ctl.globe_view, move);
    if (ctl.globe) {
      return vt->render(GlobeScene(ctl.globe_view, geometry.width(), geometry.height()), w, h);
    }
    return vt->render(PlaneScene(ctl.plane), w, h);
  };
  const std::string scene_name = globe ? "globe" : "plane";
  int rc = 0;
  auto camera_now = [&] {
    return camera_json(ctl.globe, ctl.plane, ctl.globe_view, vt->debug_view());
  };

  // The HUD: needed by the window, and by screenshots only with --hud. A window without one
  // still has the numbers in its title.
  std::unique_ptr<Hud> hud;
  if (!a.headless || a.hud) {
    auto made = Hud::create();
    if (made) {
      hud = std::move(*made);
    } else if (a.hud) {
      return report_error(made.error());
    } else {
      std::fprintf(stderr, "vts view: warning: no HUD in the window: %s\n",
                   made.error().message.c_str());
    }
  }
  // The screenshot: the last frame, with the HUD drawn over it when --hud asks.
  auto write_screenshot = [&](const std::vector<std::string>& lines) -> int {
    Image img = vt->read_image();
    if (a.hud) {
      if (auto s = hud->draw_onto(img, lines, hud_scale(img.height)); !s)
        return report_error(s.error());
    }
    if (auto w = write_png(a.screenshot, img); !w) return report_error(w.error());
    return 0;
  };

  if (a.headless) {
    std::vector<FrameStats> frames;
    std::optional<std::uint64_t> complete_at;
    for (int i = 0; i < a.frames; ++i) {
      const FrameStats st = render(double(i), a.width, a.height, true);
      frames.push_back(st);
      if (st.complete && !complete_at) complete_at = st.frame;
      if (st.complete && a.until_complete) break;
      if (st.pending > 0) ::usleep(2000);  // the decode pool works on its own threads
    }
    // A shader variant the driver refused leaves empty frames: say why instead of a black image.
    if (auto e = vt->last_error()) return report_error(*e);
    const FrameStats& last = frames.back();
    if (!a.screenshot.empty()) {
      double uploads = 0, ms = 0;
      for (const auto& f : frames) {
        uploads += double(f.uploads);
        ms += f.frame_ms;
      }
      const double n = double(frames.size());
      rc = write_screenshot(
          hud_lines(last, uploads / n, ms / n, *vt, ctl.globe, ctl.plane, ctl.globe_view));
    }
    if (a.json) {
      nlohmann::json j;
      j["source"] = a.source;
      j["scene"] = scene_name;
      j["width"] = a.width;
      j["height"] = a.height;
      j["debug"] = debug_name(vo.debug);
      j["frames"] = nlohmann::json::array();
      for (const auto& f : frames) j["frames"].push_back(stats_json(f));
      j["complete_at"] = complete_at ? nlohmann::json(*complete_at) : nlohmann::json(nullptr);
      j["screenshot"] =
          a.screenshot.empty() ? nlohmann::json(nullptr) : nlohmann::json(a.screenshot);
      j["page_table_bytes"] = vt->page_table_gpu_bytes();
      j["physical_bytes"] = vt->physical_gpu_bytes();
      j["tile_format"] = vt->tile_format() == PixelFormat::bc1 ? "bc1" : "rgba8";
      j["gl_renderer"] = gl->info().renderer;
      j["camera"] = camera_now();
      std::printf("%s\n", j.dump(2).c_str());
    } else {
      std::printf("%s %s %dx%d: %zu frames, %s; %u resident, %u pending, hit %.1f%%%s%s\n",
                  scene_name.c_str(), a.source.c_str(), a.width, a.height, frames.size(),
                  complete_at ? ("complete at frame " + std::to_string(*complete_at)).c_str()
                              : "never complete",
                  last.resident, last.pending, last.hit_ratio * 100,
                  a.screenshot.empty() ? "" : "; screenshot ", a.screenshot.c_str());
    }
    std::fflush(stdout);
  } else {
    GLFWwindow* win = gl->window();
    glfwSetWindowUserPointer(win, &ctl);
    glfwSetMouseButtonCallback(win, on_mouse_button);
    glfwSetCursorPosCallback(win, on_cursor);
    glfwSetScrollCallback(win, on_scroll);
    glfwSetKeyCallback(win, on_key);
    std::fprintf(stderr,
                 "vts view: %s — drag: %s, scroll: zoom, right-drag or Q/E R/F: heading/tilt, "
                 "1-4: debug view, H: HUD, Esc: quit\n",
                 scene_name.c_str(), globe ? "orbit" : "pan");
    auto last_title = Clock::now(), last_line = last_title, last_frame = last_title;
    std::uint64_t uploads = 0, n = 0;
    double wall_ms = 0;
    double frame = 0;
    std::vector<std::string> lines;  // the HUD's text, refreshed with the title
    const std::atomic<bool>& quit_requested = install_stop_signals();
    while (!gl->should_close() && !quit_requested.load()) {
      gl->poll_events();
      if (ctl.debug_request) {
        vt->set_debug_view(*ctl.debug_request);
        ctl.debug_request.reset();
      }
      int w = 0, h = 0;
      gl->framebuffer_size(w, h);
      if (w < 1 || h < 1) {  // minimised
        ::usleep(20000);
        continue;
      }
      const FrameStats st = render(frame, w, h, !ctl.touched);
      frame += 1;
      vt->blit_to_screen(w, h);
      const auto now = Clock::now();
      wall_ms += std::chrono::duration<double, std::milli>(now - last_frame).count();
      last_frame = now;
      uploads += st.uploads;
      ++n;
      if (lines.empty() || now - last_title >= std::chrono::milliseconds(250)) {
        lines = hud_lines(st, double(uploads) / double(n), wall_ms / double(n), *vt, ctl.globe,
                          ctl.plane, ctl.globe_view);
        const std::string text = lines[0] + "  " + lines[1];
        glfwSetWindowTitle(win, ("vts view — " + text).c_str());
        if (now - last_line >= std::chrono::seconds(1)) {
          std::fprintf(stderr, "vts view: %s\n", text.c_str());
          last_line = now;
        }
        last_title = now;
        uploads = n = 0;
        wall_ms = 0;
      }
      if (hud && ctl.show_hud) {
        if (auto s = hud->draw(lines, w, h, hud_scale(h)); !s) {
          std::fprintf(stderr, "vts view: warning: the HUD is off: %s\n",
                       s.error().message.c_str());
          hud.reset();
        }
      }
      gl->swap_buffers();
    }
    // A key pressed in the same batch of events as Esc still counts (--print-camera shows it).
    if (ctl.debug_request) vt->set_debug_view(*ctl.debug_request);
    if (!a.screenshot.empty()) rc = write_screenshot(lines);
  }
  if (recorder && !recorder->empty()) {
    if (auto s = write_atomically(a.record, recorder->path().to_json()); !s) {
      const int failed = report_error(s.error());
      if (rc == 0) rc = failed;
    }
  }
  if (a.print_camera && rc == 0) {
    std::printf("%s\n", camera_now().dump().c_str());
    std::fflush(stdout);
  }
  vt.reset();  // GL objects go while the context is current
  gl.reset();
  return rc;
}

}  // namespace

Runner add_view(CLI::App& app) {
  auto a = std::make_shared<ViewArgs>();
  CLI::App* c = app.add_subcommand(
      "view", "View a tileset through the sparse virtual texture (window, or --headless)");
  c->add_option("source", a->source,
                "Tileset: a local archive, http://host:port/NAME (vts serve or vts cache serve), "
                "a TileJSON URL or a remote .pmtiles URL")
      ->required();
  c->add_option("--cache-dir", a->cache_dir, "Disk cache folder (as vts warm fills it)");
  c->add_option("--ram-mb", a->ram_mb, "RAM tile cache, MiB")
      ->check(CLI::Range(std::uint64_t{0}, std::uint64_t{1} << 20))
      ->capture_default_str();
  c->add_option("--scene", a->scene, "plane, globe, or FILE.json {\"scene\":..., \"camera\":{...}}")
      ->capture_default_str();
  c->add_option("--camera-path", a->camera_path, "Keyframes FILE.json {\"keys\":[...]}");
  c->add_option("--record", a->record,
                "On exit, write every frame's camera to FILE.json as a camera path (a key where "
                "it changed) that --camera-path replays");
  c->add_option("--width", a->width, "Frame width, pixels")->capture_default_str();
  c->add_option("--height", a->height, "Frame height, pixels")->capture_default_str();
  c->add_option("--slots", a->slots, "Physical texture slots")->capture_default_str();
  c->add_option("--window", a->window, "Page-table window per level (power of two)")
      ->capture_default_str();
  c->add_option("--feedback", a->feedback, "Feedback pass divisor")
      ->check(CLI::IsMember({1, 2, 4, 8, 16}))
      ->capture_default_str();
  c->add_option("--upload-tiles", a->upload_tiles, "Tile uploads per frame at most")
      ->capture_default_str();
  c->add_option("--anisotropy", a->anisotropy,
                "Anisotropic filtering: taps along the footprint's long axis (1 = isotropic)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
  c->add_option("--debug", a->debug, "Debug view")
      ->check(CLI::IsMember({"none", "levels", "physical", "page-table"}))
      ->capture_default_str();
  auto* headless = c->add_flag("--headless", a->headless, "Hidden window: render --frames frames");
  c->add_option("--frames", a->frames, "Frames to render (--headless)")->needs(headless);
  auto* screenshot =
      c->add_option("--screenshot", a->screenshot, "Write the last frame to this PNG");
  c->add_flag("--hud", a->hud,
              "Draw the HUD into the screenshot too (the window shows it until H hides it)")
      ->needs(screenshot);
  auto* json =
      c->add_flag("--json", a->json, "Print the frames' stats and the camera as JSON (--headless)")
          ->needs(headless);
  c->add_flag("--print-camera", a->print_camera,
              "On exit, print the camera as a one-key camera path (JSON, one line) that "
              "--camera-path replays")
      ->excludes(json);
  c->add_flag("--until-complete", a->until_complete,
              "Stop at the first complete frame (--headless)")
      ->needs(headless);
  return [a] { return run_view(*a); };
}

}  // namespace vts::cli
