// Subcommand registration. Each add_* function declares its options on `app` and returns the
// function that runs it once parsing succeeded; the runner returns the process exit code.
#pragma once

#include <CLI/CLI.hpp>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <utility>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"

namespace vts::cli {

using Runner = std::function<int()>;
using Adder = Runner (*)(CLI::App& app);

// The build tooling's commands (`vts-build`, linked with the builder: OpenImageIO and GDAL).
Runner add_build(CLI::App& app);
Runner add_plan(CLI::App& app);     // vts plan (cmd_plan.cpp)
Runner add_merge(CLI::App& app);    // vts merge (cmd_merge.cpp)
Runner add_extract(CLI::App& app);  // vts-build's extract: every format, tiles and levels
Runner add_export(CLI::App& app);   // vts export (cmd_export.cpp)
Runner add_bench(CLI::App& app);    // vts bench accuracy (cmd_bench.cpp): only with VTS_BUILD_BENCH

// The runtime's commands (`vts`).
Runner add_info(CLI::App& app);
Runner add_verify(CLI::App& app);
Runner add_serve(CLI::App& app);
Runner add_sign(CLI::App& app);
Runner add_cache(CLI::App& app);  // vts cache serve (cmd_cache.cpp)
Runner add_warm(CLI::App& app);
Runner add_loadtest(CLI::App& app);  // vts loadtest (cmd_loadtest.cpp)
// vts loadtest compare | merge (cmd_loadtest_tools.cpp): subcommands of `loadtest`; the runner
// runs the one that was parsed.
Runner add_loadtest_tools(CLI::App& loadtest);
Runner add_view(CLI::App& app);  // vts view (cmd_view.cpp): only when the renderer is built
// vts extract in `vts`: a tile as PNG itself, the rest handed over to vts-build (cmd_extract.cpp).
Runner add_extract_runtime(CLI::App& app);

// `vts extract`'s arguments, and its subcommand (cmd_extract.cpp): a single tile written as PNG
// (imaging::write_png) by whichever executable runs it; a whole level, or another image format,
// by `rest` (vts-build: OpenImageIO; vts: hands the command over to vts-build).
struct ExtractArgs {
  std::string archive, tile, output;
  int level = -1;
  bool with_border = false;
  int channels = 4;
};
Runner add_extract_command(CLI::App& app, std::function<int(const ExtractArgs&)> rest);

// Registers the subcommands `adders` add to `app` (with --version), parses the command line and
// runs the subcommand given: the process's exit status (entry.cpp).
int run_cli(CLI::App& app, std::span<const Adder> adders, int argc, char** argv);

// The handover of build commands from `vts` to `vts-build` (handover.cpp): the build command
// argv[1] names, else nullptr; the build commands as entries of `vts --help`; and the exec of
// `vts-build` (beside this executable, else on PATH) with the same arguments, which returns only
// when neither can be run: the exit status of the error it reports.
const char* builder_command(int argc, char** argv);
void list_builder_commands(CLI::App& app);
int hand_over_to_builder(const char* command, int argc, char** argv);

// The most a --threads option takes (0 is one per core): far above any machine's cores, below
// what makes thread creation fail.
inline constexpr unsigned kMaxThreads = 1024;

// --max-download (vts loadtest, warm, view): client::SourceOptions::max_download.
inline constexpr const char* kMaxDownloadHelp =
    "A remote .pmtiles on a host that ignores HTTP Range (answers 200 with the whole file) is "
    "downloaded once, whole, and held in RAM when it is at most this size (suffix K/M/G: binary; "
    "0: never); a bigger one fails at once. Default 256M";
inline void add_max_download_option(CLI::App* c, std::uint64_t& max_download) {
  c->add_option("--max-download", max_download, kMaxDownloadHelp)
      ->transform(CLI::AsSizeValue(false));
}

// "HOST:PORT" (HOST may be [IPv6] or empty for 0.0.0.0) for --listen / --admin.
Result<std::pair<std::string, std::uint16_t>> parse_endpoint(const std::string& s);

// Makes SIGINT and SIGTERM set the returned flag instead of killing the process, so a long
// command can stop cleanly (flush, write its output); a second signal kills as usual.
const std::atomic<bool>& install_stop_signals();

// The command line as typed ("vts loadtest http://... --viewers 64"), for reports; and as given
// to run_cli() (argc, argv), for handing the command over to vts-build.
const std::string& command_line();
std::pair<int, char**> command_arguments();

// "unknown command 'buidl'; did you mean 'build'?" when argv has a word where a subcommand of
// `app` is expected that names none (below the top level: a plain lower-case word within 2 edits
// of a subcommand, since it may be a positional argument); empty otherwise (suggest.cpp).
std::string unknown_command(CLI::App& app, int argc, char** argv);
// For CLI11's "argument(s) not expected" (`extras`, after a parse): the first --option among them
// named with the command it was given to, and the nearest option of that command if near; "" when
// no extra is an --option.
std::string unknown_option(CLI::App& app, const std::vector<std::string>& extras);

// Opens the archive an argument names; an error names the path.
Result<std::shared_ptr<archive::Reader>> open_archive(const std::string& path);

// Prints "vts: error: <message>" to stderr and returns the mapped exit code.
int report_error(const vts::Error& e);

}  // namespace vts::cli
