#include "vts/loadtest/scenario.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <variant>
#include <vector>

#include "vts/base/file_io.hpp"
#include "vts/renderer/camera_path.hpp"
#include "vts/renderer/demand.hpp"
#include "vts/renderer/globe.hpp"
#include "vts/renderer/scene.hpp"

namespace vts::loadtest {

namespace {

using namespace vts::renderer;

// A viewer's camera at one frame: on a globe or over a plane (none before the first frame).
using View = std::variant<std::monostate, GlobeView, PlaneView>;

// One viewer's camera: its path, where it starts in it, and its demand simulator.
struct ViewerCamera {
  std::optional<CameraPath> path;
  double offset = 0;          // frames: viewers replaying one file start at different places in it
  std::vector<double> moves;  // floor of the frames where the path starts a new view, sorted
  std::unique_ptr<DemandSimulator> sim;
  // The previous frame's view and tiles: a camera that has not moved wants the same tiles.
  View last_view;
  double last_bias = 0;
  std::vector<DemandTile> last_tiles;
};

struct Cameras {
  Geometry geometry;
  CameraDemandOptions options;
  bool preset = false;
  std::vector<ViewerCamera> viewers;

  Result<ViewerDemand> demand(std::uint32_t v, std::uint64_t frame, double bias) {
    ViewerCamera& c = viewers[v];
    const CameraPath& p = *c.path;
    // A file path loops; presets cover the run.
    double t = double(frame) + c.offset;
    const double first = p.first_frame(), span = p.last_frame() - first;
    if (!preset && span > 0) t = first + std::fmod(t - first, span + 1);
    ViewerDemand d;
    d.move = std::binary_search(c.moves.begin(), c.moves.end(), std::floor(t));
    const int w = options.width, h = options.height;
    const bool globe = p.has_globe() && !p.has_plane();
    const View view = globe ? View{p.globe_at(t)} : View{p.plane_at(t)};
    if (view == c.last_view && bias == c.last_bias) {
      d.tiles = c.last_tiles;
      d.reused = true;
      return d;
    }
    Result<std::vector<TileRequest>> wanted =
        globe ? c.sim->demand(
                    GlobeScene(std::get<GlobeView>(view), geometry.width(), geometry.height()), w,
                    h, bias)
              : c.sim->demand(PlaneScene(std::get<PlaneView>(view)), w, h, bias);
    if (!wanted) return wanted.error();
    d.tiles = std::move(*wanted);
    c.last_view = view;
    c.last_bias = bias;
    c.last_tiles = d.tiles;
    return d;
  }
};

bool is_preset(const std::string& name) {
  for (auto p : CameraPath::preset_names())
    if (p == name) return true;
  return false;
}

// A path that is not a preset names a camera-path file; a typo in a preset's name lands here
// too, so the error lists the presets.
Result<std::string> read_path_file(const std::string& file) {
  auto text = read_file(file);
  if (text) return text;
  std::string presets;
  for (auto p : CameraPath::preset_names())
    presets += (presets.empty() ? "" : ", ") + std::string(p);
  return make_error(ErrorCode::not_found, "--path '" + file + "' is neither a preset (" + presets +
                                              ") nor a readable camera-path file");
}

Result<CameraPath> viewer_path(const Cameras& c, const std::string& text, std::uint32_t v) {
  const CameraDemandOptions& o = c.options;
  if (!c.preset) {
    auto path = CameraPath::parse(text);
    if (!path) {
      Error e = path.error();
      e.message = "camera path '" + o.path + "': " + e.message;
      return e;
    }
    return path;
  }
  PresetOptions po;
  po.image_width = c.geometry.width();
  po.image_height = c.geometry.height();
  po.fps = o.fps;
  po.duration_s = o.duration_s;
  po.seed = o.seed * 1000003u + v;
  po.viewport_width = o.width;
  po.viewport_height = o.height;
  return CameraPath::preset(o.path, po);
}

}  // namespace

Status apply_target(const LoadTarget& t, LoadTestOptions& o) {
  o.target = t.cache == "daemon" ? t.daemon : t.url;
  if (t.cache == "daemon" && t.daemon.empty())
    return Error{
        ErrorCode::invalid_argument,
        "--cache daemon needs --daemon URL (a `vts cache serve` in front of " + t.url + ")"};
  o.cache = t.cache == "ram"    ? CacheMode::ram
            : t.cache == "disk" ? CacheMode::disk
                                : CacheMode::none;
  o.cache_dir = t.cache_dir;
  if (o.cache == CacheMode::disk && o.cache_dir.empty())
    return Error{ErrorCode::invalid_argument, "--cache disk needs --cache-dir DIR"};
  return {};
}

Result<Geometry> target_geometry(const LoadTestOptions& o) {
  auto probe = client::open_source(o.target, o.source);
  if (!probe) return probe.error();
  return (*probe)->info().info.geometry;
}

Result<CameraDemand> camera_demand(const Geometry& geometry, const CameraDemandOptions& o) {
  auto cams = std::make_shared<Cameras>(Cameras{geometry, o, is_preset(o.path), {}});
  std::string text;
  if (!cams->preset) {
    auto read = read_path_file(o.path);
    if (!read) return read.error();
    text = std::move(*read);
  }
  cams->viewers.resize(o.viewers);
  for (std::uint32_t v = 0; v < o.viewers; ++v) {
    auto path = viewer_path(*cams, text, v);
    if (!path) return path.error();
    auto sim = DemandSimulator::create(geometry, DemandOptions{o.feedback, o.anisotropy});
    if (!sim) return sim.error();
    ViewerCamera& c = cams->viewers[v];
    c.path.emplace(std::move(*path));
    for (double m : c.path->move_frames()) c.moves.push_back(std::floor(m));
    c.sim = std::make_unique<DemandSimulator>(std::move(*sim));
    if (!cams->preset) {
      const double span = c.path->last_frame() - c.path->first_frame();
      const double total = o.total_viewers ? o.total_viewers : o.viewers;
      c.offset = span > 0 ? span * double(o.first_viewer + v) / total : 0;
    }
  }
  CameraDemand d;
  d.path_name = cams->preset ? o.path : std::filesystem::path(o.path).filename().string();
  d.demand = [cams](std::uint32_t v, std::uint64_t frame, double bias) {
    return cams->demand(v, frame, bias);
  };
  return d;
}

nlohmann::json simulation_json(const LoadRunStats& run, const CameraDemandOptions& camera,
                               const std::string& cache, int retries) {
  return {{"viewer_frames", run.frames},
          {"late_frames", run.late_frames},
          {"moves_incomplete", run.moves_incomplete},
          {"idle_slots", run.idle_slots},
          {"startup_slots", run.startup_slots},
          {"abandoned", run.abandoned},
          {"demand_cpu_ms_per_frame", run.demand_cpu_ms_per_frame},
          {"demand_reused_frames", run.demand_reused},
          {"viewport", {camera.width, camera.height}},
          {"feedback_divisor", camera.feedback},
          {"anisotropy", camera.anisotropy},
          {"cache", cache},
          {"retries", retries}};
}

std::string simulation_line(const LoadRunStats& run, bool open_loop) {
  char line[512];
  std::snprintf(
      line, sizeof line,
      "simulation: %llu viewer-frames (%llu late, %llu unmoved), demand %.2f ms CPU/frame, %llu "
      "moves not at full resolution in time, %llu abandoned at the end%s\n",
      static_cast<unsigned long long>(run.frames), static_cast<unsigned long long>(run.late_frames),
      static_cast<unsigned long long>(run.demand_reused), run.demand_cpu_ms_per_frame,
      static_cast<unsigned long long>(run.moves_incomplete),
      static_cast<unsigned long long>(run.abandoned),
      open_loop ? (", " + std::to_string(run.idle_slots) + " idle slots (" +
                   std::to_string(run.startup_slots) + " more at start-up)")
                      .c_str()
                : "");
  return line;
}

}  // namespace vts::loadtest
