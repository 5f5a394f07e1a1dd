// vts loadtest compare A.json B.json: the change of each metric between two runs, regressions
// marked. vts loadtest merge A.json B.json ...: the reports of N load generators as one (exact
// counts and percentiles), with the same gates as a run.
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "commands.hpp"
#include "loadtest_gates.hpp"
#include "vts/base/file_io.hpp"
#include "vts/loadtest/load_gates.hpp"
#include "vts/loadtest/load_report.hpp"

namespace vts::cli {

namespace {

struct CompareArgs {
  std::string a, b, threshold = "10%";
  bool json = false, fail = false;
};

int run_compare(const CompareArgs& c) {
  auto threshold = loadtest::parse_fraction(c.threshold);
  if (!threshold)
    return report_error(
        make_error(ErrorCode::invalid_argument, "--threshold " + threshold.error().message));
  auto a = loadtest::read_report_file(c.a);
  if (!a) return report_error(a.error());
  auto b = loadtest::read_report_file(c.b);
  if (!b) return report_error(b.error());
  const auto changes = loadtest::compare_reports(*a, *b, *threshold);
  const nlohmann::json j = loadtest::compare_json(changes, *threshold);
  if (c.json) {
    nlohmann::json out = j;
    out["a"] = c.a;
    out["b"] = c.b;
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    std::printf("A: %s\nB: %s\n\n%s", c.a.c_str(), c.b.c_str(),
                loadtest::compare_table(changes).c_str());
    std::printf("\n%d regression(s) (worse by more than %s)\n", j["regressions"].get<int>(),
                c.threshold.c_str());
  }
  return c.fail && j["regressions"].get<int>() > 0 ? 1 : 0;
}

struct MergeArgs {
  std::vector<std::string> files;
  std::string report, title;
  bool json = false;
  GateArgs gates;
};

int run_merge(const MergeArgs& m) {
  auto gates = parse_gates(m.gates);
  if (!gates) return report_error(gates.error());
  if (!m.report.empty()) {
    const std::vector<std::filesystem::path> read(m.files.begin(), m.files.end());
    if (Status st =
            check_output_is_not_an_input(std::filesystem::path(m.report) / "index.html", read);
        !st)
      return report_error(st.error());
  }
  std::vector<loadtest::LoadReport> reports;
  for (const std::string& f : m.files) {
    auto r = loadtest::read_report_file(f);
    if (!r) return report_error(r.error());
    reports.push_back(std::move(*r));
  }
  auto merged = loadtest::merge_reports(reports);
  if (!merged) return report_error(merged.error());
  merged->command_line = command_line();
  if (!m.title.empty()) merged->title = m.title;
  if (!m.report.empty())
    if (auto st = write_gated_report(*merged, m.report, nullptr, *gates); !st)
      return report_error(st.error());
  if (m.json) {
    nlohmann::json j = loadtest::to_json(*merged);
    j["merged"] = m.files;
    const int code = check_gates(*merged, *gates, &j);
    std::printf("%s\n", j.dump(2).c_str());
    return code;
  }
  std::fputs(loadtest::summary_table(*merged).c_str(), stdout);
  std::printf("merged %zu runs\n", m.files.size());
  std::fflush(stdout);
  return check_gates(*merged, *gates, nullptr);
}

}  // namespace

Runner add_loadtest_tools(CLI::App& loadtest) {
  auto c = std::make_shared<CompareArgs>();
  CLI::App* cmp = loadtest.add_subcommand(
      "compare", "The change of each metric between two --json runs, regressions marked");
  cmp->add_option("a", c->a, "The baseline run's --json output")->required();
  cmp->add_option("b", c->b, "The new run's --json output")->required();
  cmp->add_option("--threshold", c->threshold,
                  "A change for the worse beyond this is a regression: fraction or percentage")
      ->capture_default_str();
  cmp->add_flag("--fail-on-regression", c->fail, "Exit 1 when a metric regressed");
  cmp->add_flag("--json", c->json, "Print the comparison as JSON");

  auto m = std::make_shared<MergeArgs>();
  CLI::App* mrg = loadtest.add_subcommand(
      "merge", "One report of N load generators' --json runs: exact counts and percentiles");
  mrg->add_option("files", m->files, "The generators' --json outputs")->required();
  mrg->add_option("--report", m->report, "Write the merged HTML report to DIR/index.html");
  mrg->add_option("--title", m->title, "Title of the merged report");
  mrg->add_flag("--json", m->json, "Print the merged report as JSON");
  add_gate_options(mrg, m->gates);
  return [c, m, cmp] { return cmp->parsed() ? run_compare(*c) : run_merge(*m); };
}

}  // namespace vts::cli
