// vts — the vtstream command line: one subcommand per user journey.
#include <csignal>
#include <cstdio>
#include <exception>
#include <string>

#include "commands.hpp"
#include "vts/protocol/result.hpp"

namespace vts::cli {

namespace {
std::string g_command_line;
}  // namespace

const std::string& command_line() {
  return g_command_line;
}

int report_error(const Error& e) {
  std::fprintf(stderr, "vts: error: %s\n", e.message.c_str());
  return exit_code(e.code);
}

}  // namespace vts::cli

namespace {
std::atomic<bool> g_stop{false};
extern "C" void on_stop_signal(int) {
  g_stop.store(true);
}

// Parses the command line; -1 when a subcommand is to run, else the exit status: 0 after --help
// or --version, 2 for every malformed command line (README), whatever CLI11's own code for the
// kind of mistake (105 for a value its check refused, ...).
int parse(CLI::App& app, int argc, char** argv) {
  std::string unknown = vts::cli::unknown_command(app, argc, argv);
  if (!unknown.empty()) {
    std::fprintf(stderr, "vts: error: %s\nRun with --help for the list of commands.\n",
                 unknown.c_str());
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // A mistyped option first: it may be why a required one is missing (--cache-dri).
    if (e.get_exit_code() != 0) unknown = vts::cli::unknown_option(app, app.remaining(true));
    if (!unknown.empty()) {
      std::fprintf(stderr, "vts: error: %s\nRun with --help for more information.\n",
                   unknown.c_str());
      return 2;
    }
    return app.exit(e) == 0 ? 0 : 2;
  }
  return -1;
}
}  // namespace

const std::atomic<bool>& vts::cli::install_stop_signals() {
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sa.sa_flags = SA_RESETHAND;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  return g_stop;
}

int main(int argc, char** argv) {
  CLI::App app{"vtstream: build, serve and view planet-scale textures as streamed tile pyramids",
               "vts"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "vts 0.1.0");
  std::vector<std::pair<CLI::App*, vts::cli::Runner>> runners;
  auto add = [&](vts::cli::Runner (*fn)(CLI::App&)) {
    const std::size_t before = app.get_subcommands({}).size();
    vts::cli::Runner r = fn(app);
    runners.emplace_back(app.get_subcommands({})[before], std::move(r));
  };
#ifdef VTS_HAVE_BUILDER
  add(&vts::cli::add_build);
  add(&vts::cli::add_plan);
  add(&vts::cli::add_merge);
#endif
  add(&vts::cli::add_info);
  add(&vts::cli::add_verify);
#ifdef VTS_HAVE_BUILDER
  add(&vts::cli::add_extract);
  add(&vts::cli::add_export);
#endif
  add(&vts::cli::add_serve);
  add(&vts::cli::add_sign);
  add(&vts::cli::add_cache);
  add(&vts::cli::add_warm);
  add(&vts::cli::add_loadtest);
#ifdef VTS_HAVE_ACCURACY
  add(&vts::cli::add_bench);
#endif
#ifdef VTS_HAVE_VIEWER
  add(&vts::cli::add_view);
#endif
  for (int i = 0; i < argc; ++i) {
    if (i) vts::cli::g_command_line += ' ';
    vts::cli::g_command_line += i == 0 ? "vts" : argv[i];
  }
  if (const int rc = parse(app, argc, argv); rc >= 0) return rc;
  try {
    for (auto& [sub, run] : runners)
      if (sub->parsed()) return run();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "vts: error: %s\n", e.what());
    return 70;
  }
  return 2;
}
