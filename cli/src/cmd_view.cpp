// vts view: the sparse-virtual-texture viewer. Parsing and printing only: the viewer itself
// (camera controls, HUD, frame loops, recorder) is vts::renderer::Viewer (viewer.hpp).
// Interactive by default; --headless --frames N renders N frames in a hidden window (with no
// display, on EGL; VTS_GL picks: docs/RENDERER.md) and prints per-frame stats. Screenshots are the
// virtual texture's frame alone unless --hud.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "commands.hpp"
#include "image_target.hpp"
#include "vts/base/file_io.hpp"
#include "vts/client/saved_source.hpp"
#include "vts/client/source.hpp"
#include "vts/client/tile_client.hpp"
#include "vts/imaging/web_image.hpp"
#include "vts/renderer/geo_view.hpp"
#include "vts/renderer/viewer.hpp"

namespace vts::cli {

namespace {

using namespace vts::renderer;

struct ViewArgs {
  std::string source, cache_dir, scene = "plane", camera_path, debug = "none", screenshot, record;
  std::string center;  // --center LON,LAT; --level is level (-1: not given)
  std::uint64_t ram_mb = 256;
  int width = 1280, height = 720;
  std::uint32_t slots = 256, window = 64, upload_tiles = 32;
  int feedback = 8, anisotropy = 8, level = -1, frames = 0;
  bool headless = false, json = false, until_complete = false, hud = false, print_camera = false;
  ImageTargetArgs image;  // --bounds, --zoom: an XYZ template's layout
};

void log_line(const std::string& text) {
  std::fprintf(stderr, "vts view: %s\n", text.c_str());
}

// Options first: nothing opens before they are known to be good.
Status check_args(const ViewArgs& a) {
  if (a.width < 1 || a.height < 1 || a.width > 16384 || a.height > 16384)
    return make_error(ErrorCode::invalid_argument, "--width/--height must be between 1 and 16384");
  if (a.headless && a.frames < 1)
    return make_error(ErrorCode::invalid_argument, "--headless needs --frames N (N >= 1)");
  // The files written (the camera path recorded, the screenshot): known good before a long
  // session, not at its end.
  for (const auto& [out, option] :
       {std::pair{a.record, "--record"}, {a.screenshot, "--screenshot"}})
    if (Status s = check_output_file(out, option, {a.source, a.camera_path, a.scene}); !s) return s;
  return {};
}

// The source, or offline, what a cache that saw it before knows of it.
Result<std::shared_ptr<client::TileSource>> open_source(const ViewArgs& a) {
  auto opened = open_with_layout(a.source, a.image);
  if (!opened && opened.error().code == ErrorCode::io && !a.cache_dir.empty()) {
    if (auto saved = client::load_source_info(a.cache_dir, a.source)) {
      log_line(a.source + ": " + opened.error().message + "; showing what the cache holds");
      opened = client::offline_source(std::move(*saved));
    }
  }
  if (!opened) return opened.error();
  return std::shared_ptr<client::TileSource>(std::move(*opened));
}

Result<std::shared_ptr<client::TileClient>> open_client(
    const ViewArgs& a, const std::shared_ptr<client::TileSource>& source) {
  client::TileClientOptions co;
  co.cache.ram_bytes = std::size_t(a.ram_mb) << 20;
  if (!a.cache_dir.empty()) {
    co.cache.disk = client::DiskCacheOptions{};
    co.cache.disk->dir = a.cache_dir;
  }
  auto created = client::TileClient::create(source, co);
  if (!created) return created.error();
  if (!a.cache_dir.empty() && !source->local())
    if (auto saved = client::save_source_info(a.cache_dir, a.source, source->info()); !saved)
      log_line("warning: " + saved.error().message);
  return std::shared_ptr<client::TileClient>(std::move(*created));
}

// The scene, the start camera and the camera path.
Status scene_options(const ViewArgs& a, const std::optional<std::string>& path_text,
                     const TilesetInfo& info, ViewerOptions& o) {
  o.camera = default_camera(info.geometry, a.width, a.height);
  if (auto s = parse_scene(a.scene, o.globe, o.camera); !s) return s;
  o.tiling = info.georeference ? info.georeference->tiling : Tiling::none;
  if (auto s = start_at_place(info.georeference, info.geometry, a.center, a.level, o.camera); !s)
    return make_error(s.error().code, a.source + ": " + s.error().message);
  if (!path_text) return {};
  auto p = CameraPath::parse(*path_text, o.camera);
  if (!p) return make_error(p.error().code, a.camera_path + ": " + p.error().message);
  o.path = std::move(*p);
  if (auto warning = fit_path_to_scene(*o.path, o.globe, o.tiling, info.geometry))
    log_line("warning: " + a.camera_path + *warning);
  return {};
}

ViewerOptions viewer_options(const ViewArgs& a) {
  ViewerOptions o;
  o.window.width = a.width;
  o.window.height = a.height;
  o.window.visible = !a.headless;
  o.window.vsync = !a.headless;
  o.window.title = "vts view " + a.source;
  o.texture.slots = a.slots;
  o.texture.window = a.window;
  o.texture.feedback_divisor = a.feedback;
  o.texture.upload_tiles = a.upload_tiles;
  o.texture.anisotropy = a.anisotropy;
  o.texture.debug = debug_view_from_name(a.debug);
  o.record = !a.record.empty();
  o.hud = a.hud;
  return o;
}

int write_screenshot(const Viewer& viewer, const std::string& path) {
  auto img = viewer.screenshot();
  if (!img) return report_error(img.error());
  if (auto w = imaging::write_png(path, img->width, img->height, img->rgba); !w)
    return report_error(w.error());
  return 0;
}

// --headless's screenshot and report. Returns the exit code.
int finish_headless(const Viewer& viewer, const HeadlessRun& run, const ViewArgs& a) {
  const int rc = a.screenshot.empty() ? 0 : write_screenshot(viewer, a.screenshot);
  const std::string report = a.json ? viewer.report_json(run, a.source, a.screenshot)
                                    : viewer.report_text(run, a.source, a.screenshot);
  std::printf("%s\n", report.c_str());
  std::fflush(stdout);
  return rc;
}

int run_view(const ViewArgs& a) {
  if (auto s = check_args(a); !s) return report_error(s.error());
  std::optional<std::string> path_text;
  if (!a.camera_path.empty()) {
    auto t = read_file(a.camera_path);
    if (!t)
      return report_error(
          make_error(ErrorCode::not_found, "--camera-path " + a.camera_path + ": cannot be read"));
    path_text = std::move(*t);
  }
  auto source = open_source(a);
  if (!source) return report_error(source.error());
  const Geometry geometry = (*source)->info().info.geometry;
  ViewerOptions o = viewer_options(a);
  if (auto s = scene_options(a, path_text, (*source)->info().info, o); !s)
    return report_error(s.error());
  auto tiles = open_client(a, *source);
  if (!tiles) return report_error(tiles.error());
  auto made = Viewer::create(std::move(*tiles), geometry, std::move(o), log_line);
  if (!made) return report_error(made.error());
  Viewer& viewer = **made;
  int rc = 0;
  if (a.headless) {
    auto run = viewer.run_headless(a.frames, a.until_complete);
    if (!run) return report_error(run.error());
    rc = finish_headless(viewer, *run, a);
  } else {
    viewer.run_interactive(install_stop_signals());
    if (!a.screenshot.empty()) rc = write_screenshot(viewer, a.screenshot);
  }
  if (auto path = viewer.recorded()) {
    if (auto s = write_file_atomically(a.record, path->to_json()); !s) {
      const int failed = report_error(make_error(s.error().code, "--record: " + s.error().message));
      if (rc == 0) rc = failed;
    }
  }
  if (a.print_camera && rc == 0) {
    std::printf("%s\n", viewer.camera_json().c_str());
    std::fflush(stdout);
  }
  return rc;
}

}  // namespace

Runner add_view(CLI::App& app) {
  auto a = std::make_shared<ViewArgs>();
  CLI::App* c = app.add_subcommand(
      "view", "View a tileset through the sparse virtual texture (window, or --headless)");
  c->add_option("source", a->source,
                "Tileset: a local archive (ours or stock raster PMTiles), http://host:port/NAME "
                "(vts serve or cache serve), a TileJSON, a {z}/{x}/{y} template or a .pmtiles URL")
      ->required();
  add_image_target_options(c, a->image);
  c->add_option("--cache-dir", a->cache_dir, "Disk cache folder (as vts warm fills it)");
  c->add_option("--ram-mb", a->ram_mb, "RAM tile cache, MiB")
      ->check(CLI::Range(std::uint64_t{0}, std::uint64_t{1} << 20))
      ->capture_default_str();
  c->add_option("--scene", a->scene, "plane, globe, or FILE.json {\"scene\":..., \"camera\":{...}}")
      ->capture_default_str();
  c->add_option("--camera-path", a->camera_path, "Keyframes FILE.json {\"keys\":[...]}");
  c->add_option("--center", a->center, "Georeferenced tilesets: start over LON,LAT (degrees)");
  c->add_option("--level", a->level,
                "Georeferenced tilesets: start at about one texel of this level per pixel")
      ->check(CLI::Range(0, Geometry::kMaxZoom));
  c->add_option("--record", a->record,
                "On exit, write every frame's camera to FILE.json as a camera path (a key where "
                "it changed) that --camera-path replays");
  c->add_option("--width", a->width, "Frame width, pixels")->capture_default_str();
  c->add_option("--height", a->height, "Frame height, pixels")->capture_default_str();
  c->add_option("--slots", a->slots, "Physical texture slots")
      ->check(CLI::Range(2u, renderer::VirtualTextureOptions::kMaxSlots))
      ->capture_default_str();
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
  c->add_flag("--until-complete", a->until_complete, "Stop at the first complete frame")
      ->needs(headless);
  return [a] { return run_view(*a); };
}

}  // namespace vts::cli
