// The viewer behind `vts view`: a window (or a hidden one), a VirtualTexture on a plane or globe
// scene, a camera driven by a camera path, the mouse and keys (CameraControls), or nothing, the
// HUD, and the headless and interactive frame loops.
//
// Thread safety: GL-thread only; create, run and destroy a Viewer on one thread.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tiling.hpp"
#include "vts/renderer/camera_path.hpp"
#include "vts/renderer/gl_context.hpp"
#include "vts/renderer/hud.hpp"
#include "vts/renderer/viewer_controls.hpp"
#include "vts/renderer/virtual_texture.hpp"

namespace vts::renderer {

// "none", "levels", "physical", "page-table"; an unknown name is none.
DebugView debug_view_from_name(const std::string& name);
const char* debug_view_name(DebugView view);

struct ViewerOptions {
  GlContextOptions window;  // visible = false for headless
  VirtualTextureOptions texture;
  bool globe = false;
  CameraKey camera;                // the start camera
  std::optional<CameraPath> path;  // followed until the user moves the camera
  bool record = false;             // keep every frame's camera (recorded())
  bool hud = false;                // a HUD even without a visible window (screenshots with it)
  // The tileset's scheme (TilesetInfo::georeference): the plane's HUD shows the longitude and
  // latitude at the cursor (at the screen centre before the cursor is seen, and headless); the
  // globe refuses WebMercatorQuad (check_globe_tiling).
  Tiling tiling = Tiling::none;
};

// What a headless run rendered.
struct HeadlessRun {
  std::vector<FrameStats> frames;
  std::optional<std::uint64_t> complete_at;  // the first complete frame
};

class Viewer {
 public:
  // Messages for the user (progress lines, warnings), without a program-name prefix.
  using Log = std::function<void(const std::string&)>;

  // Errors: the window or context (GlContext::create), the virtual texture
  // (VirtualTexture::create), the HUD when options.hud asks for one; a globe of a scheme
  // check_globe_tiling() refuses (before any window opens). A visible window whose HUD
  // fails to build only logs a warning.
  static Result<std::unique_ptr<Viewer>> create(std::shared_ptr<client::TileClient> tiles,
                                                const Geometry& geometry, ViewerOptions options,
                                                Log log);
  ~Viewer();
  Viewer(const Viewer&) = delete;
  Viewer& operator=(const Viewer&) = delete;

  // Renders up to `frames` frames (>= 1) along the path, stopping at the first complete one with
  // until_complete. Error: the virtual texture's last_error() (a refused shader variant).
  Result<HeadlessRun> run_headless(int frames, bool until_complete);
  // Renders frames in the window with the mouse and keys bound until the window closes or `quit`
  // is set. Logs the controls once and the HUD's first two lines every second.
  void run_interactive(const std::atomic<bool>& quit);

  // The last frame (sRGB RGBA8), with the HUD of the last frames drawn over it when options.hud.
  Result<Image> screenshot() const;
  // The camera as a one-key camera path that --camera-path replays (compact JSON), plus "scene"
  // and "debug" (which CameraPath ignores).
  std::string camera_json() const;
  // `vts view --headless --json`'s report of `run` (JSON, indented by 2).
  std::string report_json(const HeadlessRun& run, const std::string& source,
                          const std::string& screenshot) const;
  // `vts view --headless`'s one-line summary of `run` (no newline): scene, source, size, frames,
  // the first complete frame, the last frame's residency and hit ratio, the screenshot if any.
  std::string report_text(const HeadlessRun& run, const std::string& source,
                          const std::string& screenshot) const;
  // Every rendered frame's camera; nullopt without options.record or before the first frame.
  std::optional<CameraPath> recorded() const;

  bool globe() const { return controls_.globe(); }
  CameraControls& controls() { return controls_; }
  VirtualTexture& texture() { return *vt_; }
  GlContext& context() { return *gl_; }
  // The HUD's text: of the last headless run (per-frame averages over it), or as last shown.
  const std::vector<std::string>& hud_text() const { return lines_; }

 private:
  Viewer(ViewerOptions options, const Geometry& geometry, Log log);
  FrameStats render(double frame, int width, int height, bool follow_path);
  // For a width x height frame (the cursor's place on a georeferenced plane).
  std::vector<std::string> hud_lines_now(const FrameStats& st, double uploads, double ms, int width,
                                         int height) const;
  void interactive_frame(double frame, int width, int height);

  ViewerOptions options_;
  Geometry geometry_;
  Log log_;
  CameraControls controls_;
  std::vector<double> path_moves_;  // frames a followed path starts a new view at
  std::optional<CameraRecorder> recorder_;
  std::vector<std::string> lines_;
  std::unique_ptr<GlContext> gl_;
  std::unique_ptr<VirtualTexture> vt_;
  std::unique_ptr<Hud> hud_;
  // Interactive loop state: the HUD's averages since the last refresh.
  std::chrono::steady_clock::time_point last_title_, last_line_, last_frame_;
  std::uint64_t uploads_ = 0, counted_ = 0;
  double wall_ms_ = 0;
  bool tile_error_logged_ = false;  // the first tile error went to the log
};

}  // namespace vts::renderer
