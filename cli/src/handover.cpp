// `vts build ...` and the other build commands: `vts` lists them in its --help and hands them
// over to `vts-build` (the executable beside it, else the one on PATH) by exec, with the same
// arguments, so the process, its stdin/stdout/stderr, its signals and its exit status are the
// builder's own. `vts extract` is the runtime's own for a tile as PNG and hands the rest over.
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "commands.hpp"

namespace vts::cli {

namespace {

struct BuilderCommand {
  const char* name;
  const char* help;
};

// In the order `vts --help` lists them; the texts are those of the builder's own subcommands.
constexpr BuilderCommand kBuilderCommands[] = {
    {"build", "Cut images into a tile pyramid archive (PMTiles)"},
    {"plan", "Fix a build once for many machines: its options, inputs and shards, in a JSON plan"},
    {"merge", "Merge the parts of a sharded build (vts plan) into the archive vts build writes"},
    {"export",
     "Write an archive's tiles as standard web images (PNG, WebP, JPEG) in a raster PMTiles "
     "archive or a {z}/{x}/{y} folder, for stock web maps"},
    {"bench", "Measure vtstream itself"},
};

}  // namespace

const char* builder_command(int argc, char** argv) {
  if (argc < 2) return nullptr;
  const std::string_view word = argv[1];
  for (const BuilderCommand& c : kBuilderCommands)
    if (word == c.name) return c.name;
  return nullptr;
}

void list_builder_commands(CLI::App& app) {
  for (const BuilderCommand& c : kBuilderCommands)
    app.add_subcommand(c.name, c.help)->allow_extras()->group("Subcommands");
}

int hand_over_to_builder(const char* command, int argc, char** argv) {
  std::vector<char*> args(argv, argv + argc);
  args.push_back(nullptr);
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  std::string beside;
  if (!ec) {
    beside = (self.parent_path() / "vts-build").string();
    args[0] = beside.data();
    ::execv(beside.c_str(), args.data());
  }
  static char name[] = "vts-build";
  args[0] = name;
  ::execvp(name, args.data());
  const int err = errno;
  return report_error(make_error(
      ErrorCode::unsupported,
      std::string("'vts ") + command + "' is part of the build tooling, vts-build, which is not " +
          "installed: not beside " + (ec ? std::string("this vts") : "'" + self.string() + "'") +
          " nor on PATH (" + std::strerror(err) +
          "); build vtstream with -DVTS_BUILD_BUILDER=ON or install vts-build"));
}

Runner add_extract_runtime(CLI::App& app) {
  return add_extract_command(app, [](const ExtractArgs&) {
    const auto [argc, argv] = command_arguments();
    return hand_over_to_builder("extract", argc, argv);
  });
}

}  // namespace vts::cli
