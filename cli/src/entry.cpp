// The entry shared by `vts` and `vts-build`: the helpers every command uses (the command line as
// typed, error reporting, stop signals, opening an archive named by an argument) and run_cli(),
// which parses a command line against a set of subcommands and runs the one given.
#include <csignal>
#include <cstdio>
#include <exception>
#include <string>

#include "commands.hpp"
#include "vts/store/location.hpp"
#include "vts/store/open.hpp"

namespace vts::cli {

namespace {
std::string g_command_line;
int g_argc = 0;
char** g_argv = nullptr;
std::atomic<bool> g_stop{false};
extern "C" void on_stop_signal(int) {
  g_stop.store(true);
}

// Parses the command line; -1 when a subcommand is to run, else the exit status: 0 after --help
// or --version, 2 for every malformed command line (README), whatever CLI11's own code for the
// kind of mistake (105 for a value its check refused, ...).
int parse(CLI::App& app, int argc, char** argv) {
  std::string unknown = unknown_command(app, argc, argv);
  if (!unknown.empty()) {
    std::fprintf(stderr, "vts: error: %s\nRun with --help for the list of commands.\n",
                 unknown.c_str());
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // A mistyped option first: it may be why a required one is missing (--cache-dri).
    if (e.get_exit_code() != 0) unknown = unknown_option(app, app.remaining(true));
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

const std::string& command_line() {
  return g_command_line;
}

std::pair<int, char**> command_arguments() {
  return {g_argc, g_argv};
}

int report_error(const Error& e) {
  std::fprintf(stderr, "vts: error: %s\n", e.message.c_str());
  return exit_code(e.code);
}

const std::atomic<bool>& install_stop_signals() {
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sa.sa_flags = SA_RESETHAND;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  return g_stop;
}

Result<std::shared_ptr<archive::Reader>> open_archive(const std::string& path) {
  // A local file or set, or one in an object store (credentials from the AWS environment).
  auto options = store::is_remote(path) ? store::StoreOptions::from_environment()
                                        : Result<store::StoreOptions>(store::StoreOptions{});
  if (!options) return std::move(options).error();
  auto r = store::open_reader(path, *options);
  if (!r) {
    Error e = std::move(r).error();
    e.message = "'" + path + "': " + e.message;
    return e;
  }
  return r;
}

int run_cli(CLI::App& app, std::span<const Adder> adders, int argc, char** argv) {
  app.require_subcommand(1);
  app.set_version_flag("--version", "vts 0.1.0");
  std::vector<std::pair<CLI::App*, Runner>> runners;
  for (Adder add : adders) {
    const std::size_t before = app.get_subcommands({}).size();
    Runner r = add(app);
    runners.emplace_back(app.get_subcommands({})[before], std::move(r));
  }
  g_argc = argc;
  g_argv = argv;
  for (int i = 0; i < argc; ++i) {
    if (i) g_command_line += ' ';
    g_command_line += i == 0 ? "vts" : argv[i];
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

}  // namespace vts::cli
