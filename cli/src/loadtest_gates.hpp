// The CI options of `vts loadtest` and `vts loadtest merge`: gates (--max-error-rate, --slo) and,
// for a run that is one of N load generators, --generators / --generator-index.
#pragma once

#include <CLI/CLI.hpp>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/loadtest/load_gates.hpp"

namespace vts::cli {

struct GateArgs {
  std::string max_error_rate;  // empty: loadtest::kDefaultMaxErrorRate
  std::vector<std::string> slo;
};

void add_gate_options(CLI::App* c, GateArgs& g);
// The gates to check: --slo in order, then the error rate gate. invalid_argument (exit 2) for a
// malformed --slo or --max-error-rate.
Result<std::vector<loadtest::Gate>> parse_gates(const GateArgs& g);
// Checks the gates, adds "gates" {passed, results} to *json when given, prints the one-line
// reason to stderr when one failed. Returns 0, or 1 when a gate failed.
int check_gates(const loadtest::LoadReport& report, const std::vector<loadtest::Gate>& gates,
                nlohmann::json* json);
// --report DIR: the HTML report with the gates' verdict at its top (write_html_report).
Status write_gated_report(const loadtest::LoadReport& report, const std::string& dir,
                          const loadtest::LoadReport* baseline,
                          const std::vector<loadtest::Gate>& gates);

struct GeneratorArgs {
  std::uint32_t generators = 1;
  std::optional<std::uint64_t> index;  // default: $JOB_COMPLETION_INDEX, $SLURM_ARRAY_TASK_ID...
};

void add_generator_options(CLI::App* c, GeneratorArgs& g);

// This generator's share of a load of `viewers` viewers at `rate` (totals over all generators).
struct GeneratorShare {
  std::uint32_t index = 0, generators = 1;
  std::uint32_t first_viewer = 0, viewers = 0;  // viewers [first, first + viewers) of the total
  std::uint64_t seed = 0;                       // seed + index
  double rate = 0;                              // rate * viewers / total viewers
};
// invalid_argument (exit 2) for an index >= generators, fewer viewers than generators, no index
// for generators > 1.
Result<GeneratorShare> generator_share(const GeneratorArgs& g, std::uint32_t viewers,
                                       std::uint64_t seed, double rate);
nlohmann::json generator_json(const GeneratorShare& s);

}  // namespace vts::cli
