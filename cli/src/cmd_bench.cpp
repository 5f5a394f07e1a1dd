// vts bench accuracy: what accuracy costs in time (docs/ACCURACY.md). Thin glue over vts::accuracy.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "vts/accuracy/accuracy.hpp"
#include "vts/base/file_io.hpp"

namespace vts::cli {
namespace {

struct BenchArgs {
  std::string input, report, size, work_dir;
  std::vector<std::string> tables;
  bool quick = false, json = false, quiet = false;
};

int run_accuracy_bench(const BenchArgs& a) {
  accuracy::AccuracyOptions o;
  o.input = a.input;
  o.tables = a.tables;
  o.quick = a.quick;
  o.work_dir = a.work_dir;
  o.keep_work_dir = !a.work_dir.empty();
  if (!a.size.empty()) {
    int consumed = 0;
    if (std::sscanf(a.size.c_str(), "%dx%d%n", &o.width, &o.height, &consumed) != 2 ||
        consumed != int(a.size.size()) || o.width < 1 || o.height < 1)
      return report_error(Error{ErrorCode::invalid_argument,
                                "--size '" + a.size + "' is not of the form WxH, e.g. 640x400"});
  }
  if (!a.quiet) {
    o.progress = [](const std::string& line) {
      std::fprintf(stderr, "[accuracy] %s\n", line.c_str());
    };
  }
  if (!a.report.empty()) {
    const std::filesystem::path input = a.input, dir = a.report;
    for (const char* name : {"report.md", "report.json"})
      if (Status s = check_output_is_not_an_input(dir / name, {&input, 1}); !s)
        return report_error(s.error());
  }
  auto report = accuracy::run_accuracy(o);
  if (!report) return report_error(report.error());
  report->command = command_line();
  if (!a.report.empty()) {
    if (Status s = accuracy::write_report(*report, a.report); !s) return report_error(s.error());
    if (!a.quiet) std::fprintf(stderr, "[accuracy] report written to %s\n", a.report.c_str());
  }
  if (a.json) {
    std::printf("%s\n", accuracy::to_json(*report).c_str());
  } else {
    std::printf("%s",
                accuracy::to_markdown(*report, a.report.empty() ? "" : a.report + "/").c_str());
  }
  int failed = 0;
  for (const auto& s : report->skipped) {
    std::fprintf(stderr, "vts: %s table %s: %s\n", s.failed ? "error:" : "note:", s.id.c_str(),
                 s.reason.c_str());
    failed += s.failed ? 1 : 0;
  }
  return failed > 0 ? exit_code(ErrorCode::internal) : 0;
}

}  // namespace

Runner add_bench(CLI::App& app) {
  auto a = std::make_shared<BenchArgs>();
  CLI::App* c = app.add_subcommand("bench", "Measure vtstream itself");
  c->require_subcommand(1);
  CLI::App* acc = c->add_subcommand(
      "accuracy",
      "What accuracy costs in time: codec, feedback resolution, filtering, addressing precision, "
      "downsampling and warp resampling tables (docs/ACCURACY.md)");
  acc->add_option("--input", a->input,
                  "Source image (default: the Earth, /usr/share/xplanet/images/earth.jpg)");
  acc->add_option("--report", a->report,
                  "Write report.md, report.json and the SVG plots into this directory");
  acc->add_option(
         "--tables", a->tables,
         "Tables to run (default all): codec, feedback, filtering, addressing, downsample, "
         "resampling")
      ->delimiter(',')
      ->check(CLI::IsMember(
          {"codec", "feedback", "filtering", "addressing", "downsample", "resampling"}));
  acc->add_option("--size", a->size, "Viewport of the GL tables, WxH (default 640x400)");
  acc->add_flag("--quick", a->quick,
                "Fewest settings, views and frames on a small viewport (what the tests run)");
  acc->add_option("--work-dir", a->work_dir, "Keep the scratch archives in this directory");
  acc->add_flag("--json", a->json, "Print the report as JSON");
  acc->add_flag("-q,--quiet", a->quiet, "No progress lines");
  return [a] { return run_accuracy_bench(*a); };
}

}  // namespace vts::cli
