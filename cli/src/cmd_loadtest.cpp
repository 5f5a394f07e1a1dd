// vts loadtest: simulated viewers on camera paths against a tile server, and a report of how
// long a person waits. Parses the arguments, runs the load engine (vts/loadtest/) with the
// viewers' camera demand (scenario.hpp), prints the results (terminal or --json) and writes the
// HTML report.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "commands.hpp"
#include "image_target.hpp"
#include "loadtest_gates.hpp"
#include "progress.hpp"
#include "vts/base/file_io.hpp"
#include "vts/loadtest/load_report.hpp"
#include "vts/loadtest/load_test.hpp"
#include "vts/loadtest/scenario.hpp"

namespace vts::cli {

namespace {

struct LoadArgs {
  std::string url, path = "flyover", cache = "none", cache_dir, daemon, report, title, baseline;
  std::uint32_t viewers = 8;
  double duration = 30, fps = 30, rate = 0, timeout_s = 30;
  int width = 1280, height = 720, feedback = 8, anisotropy = 8, retries = 0, threads = 0;
  std::uint64_t ram_mb = 64;
  std::uint64_t seed = 1;
  bool json = false, quiet = false, decode = false;
  ImageTargetArgs image;
  std::string command_line;
  GateArgs gates;
  GeneratorArgs generator;
  GeneratorShare share;  // from `generator`, once parsed
};

// One line a second: redrawn in place on a terminal, appended elsewhere (not with --json).
std::function<void(const loadtest::LoadProgress&)> progress_printer(const LoadArgs& a, bool bar) {
  if (a.quiet) return {};
  return [bar, json = a.json, duration = a.duration](const loadtest::LoadProgress& p) {
    const std::string line = loadtest::progress_text(p, duration);
    if (bar)
      std::fprintf(stderr, "\r\033[K%s", line.c_str());
    else if (!json)
      std::fprintf(stderr, "%s\n", line.c_str());
  };
}

loadtest::CameraDemandOptions camera_options(const LoadArgs& a) {
  loadtest::CameraDemandOptions c;
  c.path = a.path;
  c.viewers = a.share.viewers;
  c.first_viewer = a.share.first_viewer;
  c.total_viewers = a.viewers;
  c.fps = a.fps;
  c.duration_s = a.duration;
  c.seed = a.share.seed;
  c.width = a.width;
  c.height = a.height;
  c.feedback = a.feedback;
  c.anisotropy = a.anisotropy;
  return c;
}

Result<loadtest::LoadTestOptions> load_options(const LoadArgs& a) {
  loadtest::LoadTestOptions o;
  if (auto st = loadtest::apply_target({a.url, a.cache, a.cache_dir, a.daemon}, o); !st)
    return st.error();
  if (auto st = apply_image_target(a.image, o.source); !st) return st.error();
  o.decode = a.decode;
  o.viewers = a.share.viewers;
  o.fps = a.fps;
  o.duration_s = a.duration;
  o.rate = a.share.rate;
  o.ram_bytes = std::size_t(a.ram_mb) << 20;
  o.threads = a.threads;
  o.title = a.title;
  o.command_line = a.command_line;
  // A load tester shows the server's failures: no silent retries unless asked for.
  o.source.fetcher.max_attempts = a.retries + 1;
  o.source.fetcher.request_timeout = std::chrono::milliseconds(std::llround(a.timeout_s * 1000));
  return o;
}

// Prints the results (JSON or tables) with the gates' verdict; returns check_gates()'s code.
int print_result(const LoadArgs& a, const loadtest::LoadTestResult& result,
                 const std::vector<loadtest::Gate>& gates) {
  const std::string report_file = (std::filesystem::path(a.report) / "index.html").string();
  if (a.json) {
    nlohmann::json j = loadtest::to_json(result.report);
    j["simulation"] = loadtest::simulation_json(result.run, camera_options(a), a.cache, a.retries);
    if (a.share.generators > 1) j["generator"] = generator_json(a.share);
    if (!a.report.empty()) j["report"] = report_file;
    const int code = check_gates(result.report, gates, &j);
    std::printf("%s\n", j.dump(2).c_str());
    return code;
  }
  std::fputs(loadtest::summary_table(result.report).c_str(), stdout);
  std::fputs(loadtest::simulation_line(result.run, a.rate > 0).c_str(), stdout);
  if (!a.report.empty()) std::printf("report: %s\n", report_file.c_str());
  std::fflush(stdout);
  return check_gates(result.report, gates, nullptr);
}

int run(LoadArgs& a) {
  auto gates = parse_gates(a.gates);
  if (!gates) return report_error(gates.error());
  if (!a.report.empty()) {
    // The report written is none of the files read: the target, the camera path, the baseline.
    const std::filesystem::path read[] = {a.url, a.path, a.baseline};
    if (Status st =
            check_output_is_not_an_input(std::filesystem::path(a.report) / "index.html", read);
        !st)
      return report_error(st.error());
  }
  auto share = generator_share(a.generator, a.viewers, a.seed, a.rate);
  if (!share) return report_error(share.error());
  a.share = *share;
  std::optional<loadtest::LoadReport> baseline;
  if (!a.baseline.empty()) {
    auto b = loadtest::read_report_file(a.baseline);
    if (!b) return report_error(b.error());
    baseline = std::move(*b);
  }
  const std::atomic<bool>& stop = install_stop_signals();
  auto o = load_options(a);
  if (!o) return report_error(o.error());
  o->stop = &stop;
  auto geometry = loadtest::target_geometry(*o);
  if (!geometry) return report_error(geometry.error());
  auto cameras = loadtest::camera_demand(*geometry, camera_options(a));
  if (!cameras) return report_error(cameras.error());
  o->path_name = cameras->path_name;
  const bool bar = !a.quiet && !a.json && ProgressBar::stderr_is_terminal();
  o->progress = progress_printer(a, bar);
  auto result = loadtest::run_load_test(*o, cameras->demand);
  if (bar) std::fprintf(stderr, "\r\033[K");
  if (!result) return report_error(result.error());
  result->report.target = a.url;
  const loadtest::LoadReport* base = baseline ? &*baseline : nullptr;
  if (!a.report.empty())
    if (auto st = write_gated_report(result->report, a.report, base, *gates); !st)
      return report_error(st.error());
  const int code = print_result(a, *result, *gates);
  return stop.load() ? 130 : code;
}

// Runs compare or merge when one was named, else the load test.
Runner loadtest_runner(const std::shared_ptr<LoadArgs>& a, CLI::App* c) {
  Runner tools = add_loadtest_tools(*c);
  return [a, c, tools] {
    if (!c->get_subcommands().empty()) return tools();
    if (a->url.empty()) {
      std::fprintf(stderr,
                   "vts: error: loadtest: url is required (or: vts loadtest compare | merge)\n");
      return 2;
    }
    a->command_line = command_line();
    return run(*a);
  };
}

// The simulated viewer's view: the feedback pass it would render.
void add_view_options(CLI::App* c, LoadArgs& a) {
  c->add_option("--width", a.width, "Viewport width, pixels")
      ->capture_default_str()
      ->check(CLI::Range(1, 16384));
  c->add_option("--height", a.height, "Viewport height, pixels")
      ->capture_default_str()
      ->check(CLI::Range(1, 16384));
  c->add_option("--feedback", a.feedback, "Feedback resolution 1/K (1, 2, 4, 8, 16)")
      ->capture_default_str()
      ->check(CLI::IsMember({1, 2, 4, 8, 16}));
  c->add_option("--anisotropy", a.anisotropy, "Anisotropic taps the viewer uses (1-16)")
      ->capture_default_str()
      ->check(CLI::Range(1, 16));
}

}  // namespace

Runner add_loadtest(CLI::App& app) {
  auto a = std::make_shared<LoadArgs>();
  CLI::App* c = app.add_subcommand(
      "loadtest", "Simulated viewers on camera paths against a tile server: streaming latency");
  c->add_option("url", a->url,
                "Tileset URL (http://host:port/NAME), TileJSON, {z}/{x}/{y} template, .pmtiles");
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
  c->add_option("--baseline", a->baseline,
                "An earlier run's --json output: the report overlays it and shows the change");
  add_view_options(c, *a);
  c->add_option("--retries", a->retries, "Retries of a failed request (0: every failure counts)")
      ->capture_default_str()
      ->check(CLI::Range(0, 10));
  c->add_option("--timeout", a->timeout_s,
                "Seconds a request may take before it fails as an error of kind timeout")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 3600.0));
  c->add_option("--seed", a->seed, "Seed of the presets' places")->capture_default_str();
  c->add_option("--threads", a->threads, "Driver threads (0: one per core)")
      ->check(CLI::Range(0, int(kMaxThreads)))
      ->capture_default_str();
  add_image_target_options(c, a->image);
  c->add_flag("--decode", a->decode, "Decode image tiles; undecodable ones count as errors");
  c->add_flag("--json", a->json, "Print the results as JSON");
  c->add_flag("--quiet", a->quiet, "No progress lines");
  add_gate_options(c, a->gates);
  add_generator_options(c, a->generator);
  return loadtest_runner(a, c);
}

}  // namespace vts::cli
