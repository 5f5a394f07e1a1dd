// vts loadtest: simulated viewers on camera paths against a tile server, and a report of how
// long a person waits. Thin glue: the camera path (renderer's CameraPath, a preset or a file)
// and the CPU demand simulator (renderer's DemandSimulator: the feedback pass's rule, no GL)
// turn each viewer's frame into tile demand; the client's load engine (load_test.hpp) streams it
// through the real client stack and measures; load_report.hpp prints and writes the results.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "vts/loadtest/load_report.hpp"
#include "vts/loadtest/load_test.hpp"
#include "vts/client/source.hpp"
#include "vts/renderer/camera_path.hpp"
#include "vts/renderer/demand.hpp"
#include "vts/renderer/globe.hpp"
#include "vts/renderer/scene.hpp"

namespace vts::cli {

namespace {

using namespace vts::renderer;

struct LoadArgs {
  std::string url, path = "flyover", cache = "none", cache_dir, daemon, report, title;
  std::uint32_t viewers = 8;
  double duration = 30, fps = 30, rate = 0;
  int width = 1280, height = 720, feedback = 8, anisotropy = 8, retries = 0, threads = 0;
  std::uint64_t ram_mb = 64;
  std::uint64_t seed = 1;
  bool json = false, quiet = false;
  std::string command_line;
};

// One viewer's camera: its path, where it starts in it, and its demand simulator.
struct ViewerCamera {
  std::optional<CameraPath> path;
  double offset = 0;          // frames: viewers replaying one file start at different places in it
  std::vector<double> moves;  // floor of the frames where the path starts a new view, sorted
  std::unique_ptr<DemandSimulator> sim;
};

// A --path that is not a preset names a camera-path file; a typo in a preset's name lands here
// too, so the error lists the presets.
Result<std::string> read_text(const std::string& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    std::string presets;
    for (auto p : CameraPath::preset_names())
      presets += (presets.empty() ? "" : ", ") + std::string(p);
    return make_error(ErrorCode::not_found, "--path '" + file + "' is neither a preset (" +
                                                presets + ") nor a readable camera-path file");
  }
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string latency_text(std::uint64_t ns) {
  char b[32];
  if (ns < 1000000)
    std::snprintf(b, sizeof b, "%.0f us", double(ns) * 1e-3);
  else if (ns < 1000000000)
    std::snprintf(b, sizeof b, "%.1f ms", double(ns) * 1e-6);
  else
    std::snprintf(b, sizeof b, "%.2f s", double(ns) * 1e-9);
  return b;
}

bool is_preset(const std::string& name) {
  for (auto p : CameraPath::preset_names())
    if (p == name) return true;
  return false;
}

int run(const LoadArgs& a) {
  const std::atomic<bool>& stop = install_stop_signals();
  client::LoadTestOptions o;
  o.target = a.cache == "daemon" ? a.daemon : a.url;
  if (a.cache == "daemon" && a.daemon.empty())
    return report_error(
        Error{ErrorCode::invalid_argument,
              "--cache daemon needs --daemon URL (a `vts cache serve` in front of " + a.url + ")"});
  o.cache = a.cache == "ram"    ? client::CacheMode::ram
            : a.cache == "disk" ? client::CacheMode::disk
                                : client::CacheMode::none;
  o.cache_dir = a.cache_dir;
  if (o.cache == client::CacheMode::disk && o.cache_dir.empty())
    return report_error(Error{ErrorCode::invalid_argument, "--cache disk needs --cache-dir DIR"});
  o.viewers = a.viewers;
  o.fps = a.fps;
  o.duration_s = a.duration;
  o.rate = a.rate;
  o.ram_bytes = std::size_t(a.ram_mb) << 20;
  o.threads = a.threads;
  o.title = a.title;
  o.command_line = a.command_line;
  o.stop = &stop;
  // A load tester shows the server's failures: no silent retries unless asked for.
  o.source.fetcher.max_attempts = a.retries + 1;

  // The tileset's geometry, from one look at the target.
  auto probe = client::open_source(o.target, o.source);
  if (!probe) return report_error(probe.error());
  const Geometry geometry = (*probe)->info().info.geometry;
  probe->reset();

  // Paths and simulators, one per viewer.
  std::vector<ViewerCamera> cams(a.viewers);
  std::string path_text;
  const bool preset = is_preset(a.path);
  if (!preset) {
    auto text = read_text(a.path);
    if (!text) return report_error(text.error());
    path_text = std::move(*text);
  }
  for (std::uint32_t v = 0; v < a.viewers; ++v) {
    Result<CameraPath> path = Error{};
    if (preset) {
      PresetOptions po;
      po.image_width = geometry.width();
      po.image_height = geometry.height();
      po.fps = a.fps;
      po.duration_s = a.duration;
      po.seed = a.seed * 1000003u + v;
      po.viewport_width = a.width;
      po.viewport_height = a.height;
      path = CameraPath::preset(a.path, po);
    } else {
      path = CameraPath::parse(path_text);
    }
    if (!path) {
      Error e = path.error();
      if (!preset) e.message = "camera path '" + a.path + "': " + e.message;
      return report_error(e);
    }
    auto sim = DemandSimulator::create(geometry, DemandOptions{a.feedback, a.anisotropy});
    if (!sim) return report_error(sim.error());
    cams[v].path.emplace(std::move(*path));
    for (double m : cams[v].path->move_frames()) cams[v].moves.push_back(std::floor(m));
    cams[v].sim = std::make_unique<DemandSimulator>(std::move(*sim));
    if (!preset) {
      const double span = cams[v].path->last_frame() - cams[v].path->first_frame();
      cams[v].offset = span > 0 ? span * double(v) / double(a.viewers) : 0;
    }
  }
  o.path_name = preset ? a.path : std::filesystem::path(a.path).filename().string();

  const auto demand = [&](std::uint32_t v, std::uint64_t frame) -> Result<client::ViewerDemand> {
    ViewerCamera& c = cams[v];
    const CameraPath& p = *c.path;
    // A file path loops; presets cover the run.
    double t = double(frame) + c.offset;
    const double first = p.first_frame(), span = p.last_frame() - first;
    if (!preset && span > 0) t = first + std::fmod(t - first, span + 1);
    client::ViewerDemand d;
    d.move = std::binary_search(c.moves.begin(), c.moves.end(), std::floor(t));
    Result<std::vector<TileRequest>> wanted = Error{};
    if (p.has_globe() && !p.has_plane()) {
      wanted = c.sim->demand(GlobeScene(p.globe_at(t), geometry.width(), geometry.height()),
                             a.width, a.height);
    } else {
      wanted = c.sim->demand(PlaneScene(p.plane_at(t)), a.width, a.height);
    }
    if (!wanted) return wanted.error();
    d.tiles.reserve(wanted->size());
    for (const TileRequest& r : *wanted)
      d.tiles.push_back(client::DemandTile{r.tile, double(r.coverage), r.direct});
    return d;
  };

  const bool bar = !a.quiet && !a.json && ProgressBar::stderr_is_terminal();
  if (!a.quiet) {
    o.progress = [&](const client::LoadProgress& p) {
      char line[256];
      std::snprintf(
          line, sizeof line,
          "[%5.0fs/%.0fs] %llu requests (%.0f/s), %llu errors, %llu in flight, p99 %s, "
          "%llu moves at full resolution%s",
          p.elapsed_s, a.duration, static_cast<unsigned long long>(p.requests), p.requests_per_s,
          static_cast<unsigned long long>(p.errors), static_cast<unsigned long long>(p.in_flight),
          latency_text(p.p99_ns).c_str(), static_cast<unsigned long long>(p.moves_complete),
          p.late_frames ? (", " + std::to_string(p.late_frames) + " late frames").c_str() : "");
      if (bar)
        std::fprintf(stderr, "\r\033[K%s", line);
      else if (!a.json)
        std::fprintf(stderr, "%s\n", line);
    };
  }

  auto result = client::run_load_test(o, demand);
  if (bar) std::fprintf(stderr, "\r\033[K");
  if (!result) return report_error(result.error());
  client::LoadReport& report = result->report;
  report.target = a.url;

  if (!a.report.empty()) {
    if (auto st = client::write_html_report(report, a.report); !st) return report_error(st.error());
  }
  const client::LoadRunStats& run = result->run;
  if (a.json) {
    nlohmann::json j = client::to_json(report);
    j["simulation"] = {{"viewer_frames", run.frames},
                       {"late_frames", run.late_frames},
                       {"moves_incomplete", run.moves_incomplete},
                       {"idle_slots", run.idle_slots},
                       {"abandoned", run.abandoned},
                       {"demand_cpu_ms_per_frame", run.demand_cpu_ms_per_frame},
                       {"viewport", {a.width, a.height}},
                       {"feedback_divisor", a.feedback},
                       {"anisotropy", a.anisotropy},
                       {"cache", a.cache},
                       {"retries", a.retries}};
    if (!a.report.empty()) j["report"] = (std::filesystem::path(a.report) / "index.html").string();
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::fputs(client::summary_table(report).c_str(), stdout);
    std::printf(
        "simulation: %llu viewer-frames (%llu late), demand %.2f ms/frame, %llu moves not at full "
        "resolution in time, %llu abandoned at the end%s\n",
        static_cast<unsigned long long>(run.frames),
        static_cast<unsigned long long>(run.late_frames), run.demand_cpu_ms_per_frame,
        static_cast<unsigned long long>(run.moves_incomplete),
        static_cast<unsigned long long>(run.abandoned),
        a.rate > 0 ? (", " + std::to_string(run.idle_slots) + " idle slots").c_str() : "");
    if (!a.report.empty())
      std::printf("report: %s\n", (std::filesystem::path(a.report) / "index.html").c_str());
  }
  if (stop.load()) return 130;
  return 0;
}

}  // namespace

Runner add_loadtest(CLI::App& app) {
  auto a = std::make_shared<LoadArgs>();
  CLI::App* c = app.add_subcommand(
      "loadtest", "Simulated viewers on camera paths against a tile server: streaming latency");
  c->add_option("url", a->url, "Tileset URL (http://host:port/NAME), remote or local .pmtiles")
      ->required();
  c->add_option("--viewers", a->viewers, "Simulated viewers")
      ->capture_default_str()
      ->check(CLI::Range(1, 10000));
  c->add_option("--path", a->path,
                "Camera path: flyover, zoom, jumps, pan, or a camera-path FILE.json")
      ->capture_default_str();
  c->add_option("--duration", a->duration, "Seconds to run")
      ->capture_default_str()
      ->check(CLI::Range(0.001, 604800.0));
  c->add_option("--fps", a->fps, "Frames per second each viewer simulates")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 1000.0));
  c->add_option("--rate", a->rate,
                "Open loop: send requests at exactly R per second (0: each viewer at its frames)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e7));
  c->add_option("--cache", a->cache, "Client caches per viewer: none, ram, disk, daemon")
      ->capture_default_str()
      ->check(CLI::IsMember({"none", "ram", "disk", "daemon"}));
  c->add_option("--cache-dir", a->cache_dir, "--cache disk: folder for the viewers' caches");
  c->add_option("--daemon", a->daemon, "--cache daemon: the `vts cache serve` URL to go through");
  c->add_option("--ram-mb", a->ram_mb, "RAM cache per viewer, MiB")->capture_default_str();
  c->add_option("--report", a->report, "Write an HTML report to DIR/index.html");
  c->add_option("--title", a->title, "Title of the report");
  c->add_option("--width", a->width, "Viewport width, pixels")
      ->capture_default_str()
      ->check(CLI::Range(1, 16384));
  c->add_option("--height", a->height, "Viewport height, pixels")
      ->capture_default_str()
      ->check(CLI::Range(1, 16384));
  c->add_option("--feedback", a->feedback, "Feedback resolution 1/K (1, 2, 4, 8, 16)")
      ->capture_default_str()
      ->check(CLI::IsMember({1, 2, 4, 8, 16}));
  c->add_option("--anisotropy", a->anisotropy, "Anisotropic taps the viewer uses (1-16)")
      ->capture_default_str()
      ->check(CLI::Range(1, 16));
  c->add_option("--retries", a->retries, "Retries of a failed request (0: every failure counts)")
      ->capture_default_str()
      ->check(CLI::Range(0, 10));
  c->add_option("--seed", a->seed, "Seed of the presets' places")->capture_default_str();
  c->add_option("--threads", a->threads, "Driver threads (0: one per core)")->capture_default_str();
  c->add_flag("--json", a->json, "Print the results as JSON");
  c->add_flag("--quiet", a->quiet, "No progress lines");
  return [a] {
    a->command_line = command_line();
    return run(*a);
  };
}

}  // namespace vts::cli
