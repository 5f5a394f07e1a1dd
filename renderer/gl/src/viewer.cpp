#include "vts/renderer/viewer.hpp"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <algorithm>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <thread>

#include "vts/renderer/geo_view.hpp"
#include "vts/renderer/gl_check.hpp"
#include "vts/renderer/globe.hpp"

namespace vts::renderer {

namespace {

using Clock = std::chrono::steady_clock;

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

nlohmann::json camera_key_json(bool globe, const PlaneView& p, const GlobeView& g,
                               DebugView debug) {
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
  return {{"scene", globe ? "globe" : "plane"}, {"debug", debug_view_name(debug)}, {"keys", {key}}};
}

// ---- GLFW input -> CameraControls ------------------------------------------------------------

CameraControls& controls_of(GLFWwindow* w) {
  return *static_cast<CameraControls*>(glfwGetWindowUserPointer(w));
}

// Window coordinates -> framebuffer pixels, and the framebuffer's size.
double window_scale(GLFWwindow* w, int& fb_width, int& fb_height) {
  int ww = 0, wh = 0;
  fb_width = fb_height = 1;
  glfwGetWindowSize(w, &ww, &wh);
  glfwGetFramebufferSize(w, &fb_width, &fb_height);
  return ww > 0 ? double(fb_width) / ww : 1.0;
}

void on_mouse_button(GLFWwindow* w, int button, int action, int) {
  CameraControls& c = controls_of(w);
  double x = 0, y = 0;
  if (!c.cursor_seen()) glfwGetCursorPos(w, &x, &y);
  const auto b = button == GLFW_MOUSE_BUTTON_LEFT    ? CameraControls::Button::left
                 : button == GLFW_MOUSE_BUTTON_RIGHT ? CameraControls::Button::right
                                                     : CameraControls::Button::other;
  c.button(b, action == GLFW_PRESS, x, y);
}

void on_cursor(GLFWwindow* w, double x, double y) {
  int fw = 1, fh = 1;
  const double k = window_scale(w, fw, fh);
  controls_of(w).cursor(x, y, k, fw, fh);
}

void on_scroll(GLFWwindow* w, double, double yoff) {
  CameraControls& c = controls_of(w);
  int fw = 1, fh = 1;
  const double k = window_scale(w, fw, fh);
  double x = 0, y = 0;
  if (!c.cursor_seen() && !c.globe()) glfwGetCursorPos(w, &x, &y);
  c.scroll(yoff, x, y, k, fw, fh);
}

CameraControls::Key key_of(int key) {
  using K = CameraControls::Key;
  switch (key) {
    case GLFW_KEY_1:
      return K::one;
    case GLFW_KEY_2:
      return K::two;
    case GLFW_KEY_3:
      return K::three;
    case GLFW_KEY_4:
      return K::four;
    case GLFW_KEY_H:
      return K::h;
    case GLFW_KEY_Q:
      return K::q;
    case GLFW_KEY_E:
      return K::e;
    case GLFW_KEY_R:
      return K::r;
    case GLFW_KEY_F:
      return K::f;
    default:
      return K::other;
  }
}

void on_key(GLFWwindow* w, int key, int, int action, int) {
  if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
  if (key == GLFW_KEY_ESCAPE) {
    glfwSetWindowShouldClose(w, GLFW_TRUE);
    return;
  }
  controls_of(w).key(key_of(key), action == GLFW_REPEAT);
}

}  // namespace

DebugView debug_view_from_name(const std::string& s) {
  if (s == "levels") return DebugView::levels;
  if (s == "physical") return DebugView::physical;
  if (s == "page-table") return DebugView::page_table;
  return DebugView::none;
}

const char* debug_view_name(DebugView v) {
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

Viewer::Viewer(ViewerOptions options, const Geometry& geometry, Log log)
    : options_(std::move(options)),
      geometry_(geometry),
      log_(std::move(log)),
      controls_(options_.globe, options_.camera, geometry.width(), geometry.height()) {
  if (options_.path) path_moves_ = options_.path->move_frames();
  if (options_.record) recorder_.emplace(options_.globe);
}

Viewer::~Viewer() {
  // GL objects go while the context is current.
  hud_.reset();
  vt_.reset();
  gl_.reset();
}

Result<std::unique_ptr<Viewer>> Viewer::create(std::shared_ptr<client::TileClient> tiles,
                                               const Geometry& geometry, ViewerOptions options,
                                               Log log) {
  if (options.globe)
    if (auto s = check_globe_tiling(options.tiling); !s) return s.error();
  std::unique_ptr<Viewer> v(new Viewer(std::move(options), geometry, std::move(log)));
  auto gl = GlContext::create(v->options_.window);
  if (!gl) return gl.error();
  v->gl_ = std::move(*gl);
  auto vt = VirtualTexture::create(std::move(tiles), geometry, v->options_.texture);
  if (!vt) return vt.error();
  v->vt_ = std::move(*vt);
  // The HUD: needed by a visible window, and by screenshots only when asked. A window without
  // one still has the numbers in its title.
  if (v->options_.window.visible || v->options_.hud) {
    auto hud = Hud::create();
    if (hud) {
      v->hud_ = std::move(*hud);
    } else if (v->options_.hud) {
      return hud.error();
    } else {
      v->log_("warning: no HUD in the window: " + hud.error().message);
    }
  }
  return v;
}

FrameStats Viewer::render(double frame, int width, int height, bool follow_path) {
  bool move = false;
  CameraControls& c = controls_;
  if (options_.path && follow_path) {
    c.plane = options_.path->plane_at(frame);
    c.globe_view = options_.path->globe_at(frame);
    move = std::binary_search(path_moves_.begin(), path_moves_.end(), frame);
  }
  if (recorder_) recorder_->add(frame, c.plane, c.globe_view, move);
  if (c.globe())
    return vt_->render(GlobeScene(c.globe_view, geometry_.width(), geometry_.height()), width,
                       height);
  return vt_->render(PlaneScene(c.plane), width, height);
}

std::vector<std::string> Viewer::hud_lines_now(const FrameStats& st, double uploads, double ms,
                                               int width, int height) const {
  HudNumbers n;
  n.resident = st.resident;
  n.pending = st.pending;
  n.uploads = uploads;
  n.frame_ms = ms;
  n.hit_ratio = st.hit_ratio;
  n.mip_bias = st.mip_bias;
  if (vt_->debug_view() != DebugView::none) n.debug = debug_view_name(vt_->debug_view());
  n.bc1 = vt_->tile_format() == PixelFormat::bc1;
  n.physical_bytes = vt_->physical_gpu_bytes();
  n.page_table_bytes = vt_->page_table_gpu_bytes();
  if (options_.tiling != Tiling::none && !controls_.globe())
    n.place = plane_place_text(options_.tiling, geometry_, controls_.plane, width, height,
                               controls_.cursor_pixel());
  return hud_lines(n, controls_.globe(), controls_.plane, controls_.globe_view);
}

Result<HeadlessRun> Viewer::run_headless(int frames, bool until_complete) {
  VTS_GL_CALL_SITE("Viewer::run_headless");
  HeadlessRun run;
  const int w = options_.window.width, h = options_.window.height;
  for (int i = 0; i < frames; ++i) {
    const FrameStats st = render(double(i), w, h, true);
    run.frames.push_back(st);
    if (st.complete && !run.complete_at) run.complete_at = st.frame;
    if (st.complete && until_complete) break;
    // The decode pool works on its own threads.
    if (st.pending > 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  // A shader variant the driver refused leaves empty frames: say why instead of a black image.
  if (auto e = vt_->last_error()) return *e;
  double uploads = 0, ms = 0;
  for (const auto& f : run.frames) {
    uploads += double(f.uploads);
    ms += f.frame_ms;
  }
  const double n = double(run.frames.size());
  if (!run.frames.empty()) lines_ = hud_lines_now(run.frames.back(), uploads / n, ms / n, w, h);
  return run;
}

void Viewer::interactive_frame(double frame, int w, int h) {
  const FrameStats st = render(frame, w, h, !controls_.touched);
  vt_->blit_to_screen(w, h);
  const auto now = Clock::now();
  wall_ms_ += std::chrono::duration<double, std::milli>(now - last_frame_).count();
  last_frame_ = now;
  uploads_ += st.uploads;
  ++counted_;
  // The first tile that cannot be shown says why (a wrong tile size, a server error); the rest
  // are counted in the HUD's error line.
  if (!tile_error_logged_) {
    if (auto e = vt_->last_tile_error()) {
      log_("warning: " + e->message + " (further tile errors are counted in the HUD)");
      tile_error_logged_ = true;
    }
  }
  if (lines_.empty() || now - last_title_ >= std::chrono::milliseconds(250)) {
    lines_ =
        hud_lines_now(st, double(uploads_) / double(counted_), wall_ms_ / double(counted_), w, h);
    const std::string text = lines_[0] + "  " + lines_[1];
    glfwSetWindowTitle(gl_->window(), ("vts view — " + text).c_str());
    if (now - last_line_ >= std::chrono::seconds(1)) {
      log_(text);
      last_line_ = now;
    }
    last_title_ = now;
    uploads_ = counted_ = 0;
    wall_ms_ = 0;
  }
  if (hud_ && controls_.show_hud) {
    if (auto s = hud_->draw(lines_, w, h, hud_scale(h)); !s) {
      log_("warning: the HUD is off: " + s.error().message);
      hud_.reset();
    }
  }
}

void Viewer::run_interactive(const std::atomic<bool>& quit) {
  VTS_GL_CALL_SITE("Viewer::run_interactive");
  GLFWwindow* win = gl_->window();
  glfwSetWindowUserPointer(win, &controls_);
  glfwSetMouseButtonCallback(win, on_mouse_button);
  glfwSetCursorPosCallback(win, on_cursor);
  glfwSetScrollCallback(win, on_scroll);
  glfwSetKeyCallback(win, on_key);
  log_(std::string(controls_.globe() ? "globe" : "plane") +
       " — drag: " + (controls_.globe() ? "orbit" : "pan") +
       ", scroll: zoom, right-drag or Q/E R/F: heading/tilt, 1-4: debug view, H: HUD, Esc: quit");
  last_title_ = last_line_ = last_frame_ = Clock::now();
  double frame = 0;
  while (!gl_->should_close() && !quit.load()) {
    gl_->poll_events();
    if (controls_.debug_request) {
      vt_->set_debug_view(DebugView(*controls_.debug_request));
      controls_.debug_request.reset();
    }
    int w = 0, h = 0;
    gl_->framebuffer_size(w, h);
    if (w < 1 || h < 1) {  // minimised
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      continue;
    }
    interactive_frame(frame, w, h);
    frame += 1;
    gl_->swap_buffers();
  }
  // A key pressed in the same batch of events as Esc still counts.
  if (controls_.debug_request) vt_->set_debug_view(DebugView(*controls_.debug_request));
  glfwSetWindowUserPointer(win, nullptr);
  glfwSetMouseButtonCallback(win, nullptr);
  glfwSetCursorPosCallback(win, nullptr);
  glfwSetScrollCallback(win, nullptr);
  glfwSetKeyCallback(win, nullptr);
}

Result<Image> Viewer::screenshot() const {
  VTS_GL_CALL_SITE("Viewer::screenshot");
  Image img = vt_->read_image();
  if (options_.hud) {
    if (!hud_) return make_error(ErrorCode::internal, "no HUD to draw into the screenshot");
    if (auto s = hud_->draw_onto(img, lines_, hud_scale(img.height)); !s) return s.error();
  }
  return img;
}

std::string Viewer::camera_json() const {
  return camera_key_json(controls_.globe(), controls_.plane, controls_.globe_view,
                         vt_->debug_view())
      .dump();
}

std::string Viewer::report_json(const HeadlessRun& run, const std::string& source,
                                const std::string& screenshot) const {
  nlohmann::json j;
  j["source"] = source;
  j["scene"] = controls_.globe() ? "globe" : "plane";
  j["width"] = options_.window.width;
  j["height"] = options_.window.height;
  j["debug"] = debug_view_name(options_.texture.debug);
  j["frames"] = nlohmann::json::array();
  for (const auto& f : run.frames) j["frames"].push_back(stats_json(f));
  j["complete_at"] = run.complete_at ? nlohmann::json(*run.complete_at) : nlohmann::json(nullptr);
  j["screenshot"] = screenshot.empty() ? nlohmann::json(nullptr) : nlohmann::json(screenshot);
  j["page_table_bytes"] = vt_->page_table_gpu_bytes();
  j["physical_bytes"] = vt_->physical_gpu_bytes();
  j["tile_format"] = vt_->tile_format() == PixelFormat::bc1 ? "bc1" : "rgba8";
  j["gl_renderer"] = gl_->info().renderer;
  j["gl_backend"] = gl_->info().backend;
  if (!gl_->info().device.empty()) j["gl_device"] = gl_->info().device;
  if (auto e = vt_->last_tile_error()) j["last_tile_error"] = e->message;
  j["camera"] =
      camera_key_json(controls_.globe(), controls_.plane, controls_.globe_view, vt_->debug_view());
  return j.dump(2);
}

std::string Viewer::report_text(const HeadlessRun& run, const std::string& source,
                                const std::string& screenshot) const {
  const FrameStats& last = run.frames.back();
  const std::string complete =
      run.complete_at ? "complete at frame " + std::to_string(*run.complete_at) : "never complete";
  char buf[160];
  std::snprintf(buf, sizeof buf, " %dx%d: %zu frames, %s; %u resident, %u pending, hit %.1f%%",
                options_.window.width, options_.window.height, run.frames.size(), complete.c_str(),
                last.resident, last.pending, last.hit_ratio * 100);
  std::string errors;
  if (auto e = vt_->last_tile_error()) {
    errors = "; " + std::to_string(last.errors) + " tile errors, the last: " + e->message;
  }
  return std::string(controls_.globe() ? "globe " : "plane ") + source + buf + errors +
         (screenshot.empty() ? "" : "; screenshot " + screenshot);
}

std::optional<CameraPath> Viewer::recorded() const {
  if (!recorder_ || recorder_->empty()) return std::nullopt;
  return recorder_->path();
}

}  // namespace vts::renderer
