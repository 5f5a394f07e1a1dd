// --max-error-rate, --slo, --generators and --generator-index (loadtest_gates.hpp).
#include "loadtest_gates.hpp"

#include <cstdio>
#include <cstdlib>

#include "progress.hpp"

namespace vts::cli {

void add_gate_options(CLI::App* c, GateArgs& g) {
  c->add_option("--max-error-rate", g.max_error_rate,
                "Exit 1 when more than R of the requests failed: a fraction (0.01) or a "
                "percentage (1%); default 1%, 100% to never fail on errors");
  c->add_option("--slo", g.slo,
                "Exit 1 unless METRIC OP VALUE holds, e.g. 'p99<200ms', 'full_res_p95<1.5s', "
                "'requests_per_s>=500' (repeatable; OP < <= > >=; see docs/LOADTEST.md)");
}

Result<std::vector<loadtest::Gate>> parse_gates(const GateArgs& g) {
  std::vector<loadtest::Gate> gates;
  for (const std::string& text : g.slo) {
    auto gate = loadtest::parse_slo(text);
    if (!gate) return gate.error();
    gates.push_back(*gate);
  }
  double rate = loadtest::kDefaultMaxErrorRate;
  if (!g.max_error_rate.empty()) {
    auto r = loadtest::parse_fraction(g.max_error_rate);
    if (!r) return make_error(ErrorCode::invalid_argument, "--max-error-rate " + r.error().message);
    rate = *r;
  }
  gates.push_back(loadtest::max_error_rate_gate(rate));
  return gates;
}

Status write_gated_report(const loadtest::LoadReport& report, const std::string& dir,
                          const loadtest::LoadReport* baseline,
                          const std::vector<loadtest::Gate>& gates) {
  const auto verdict = loadtest::evaluate_gates(report, gates);
  return loadtest::write_html_report(report, dir, baseline, &verdict);
}

int check_gates(const loadtest::LoadReport& report, const std::vector<loadtest::Gate>& gates,
                nlohmann::json* json) {
  const auto results = loadtest::evaluate_gates(report, gates);
  const std::string failure = loadtest::gate_failure_line(results);
  if (json) (*json)["gates"] = {{"passed", failure.empty()}, {"results", gates_json(results)}};
  if (failure.empty()) return 0;
  std::fprintf(stderr, "vts: %s\n", failure.c_str());
  return 1;
}

void add_generator_options(CLI::App* c, GeneratorArgs& g) {
  c->add_option("--generators", g.generators,
                "This run is one of N load generators: --viewers and --rate are the totals, this "
                "one runs its share of the viewers with seed + index")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000));
  c->add_option("--generator-index", g.index,
                "Which of the --generators this is, 0..N-1 (default: $JOB_COMPLETION_INDEX, "
                "$SLURM_ARRAY_TASK_ID or $AWS_BATCH_JOB_ARRAY_INDEX)");
}

namespace {

Result<std::uint64_t> generator_index(const GeneratorArgs& g) {
  if (g.index) return *g.index;
  if (g.generators == 1) return 0;
  auto index = array_job_index("generator index");
  if (!index) return index.error();
  if (*index) return **index;
  return make_error(ErrorCode::invalid_argument,
                    "--generators without --generator-index, $JOB_COMPLETION_INDEX, "
                    "$SLURM_ARRAY_TASK_ID or $AWS_BATCH_JOB_ARRAY_INDEX");
}

}  // namespace

Result<GeneratorShare> generator_share(const GeneratorArgs& g, std::uint32_t viewers,
                                       std::uint64_t seed, double rate) {
  auto index = generator_index(g);
  if (!index) return index.error();
  if (*index >= g.generators)
    return make_error(ErrorCode::invalid_argument, "generator index " + std::to_string(*index) +
                                                       " is not below --generators " +
                                                       std::to_string(g.generators));
  if (viewers < g.generators)
    return make_error(ErrorCode::invalid_argument,
                      "--viewers " + std::to_string(viewers) + " is fewer than --generators " +
                          std::to_string(g.generators) + " (each generator needs a viewer)");
  GeneratorShare s;
  s.index = static_cast<std::uint32_t>(*index);
  s.generators = g.generators;
  const std::uint64_t v = viewers, n = g.generators, i = s.index;
  s.first_viewer = static_cast<std::uint32_t>(v * i / n);
  s.viewers = static_cast<std::uint32_t>(v * (i + 1) / n - v * i / n);
  s.seed = seed + i;
  s.rate = rate * double(s.viewers) / double(viewers);
  return s;
}

nlohmann::json generator_json(const GeneratorShare& s) {
  return {{"index", s.index},
          {"generators", s.generators},
          {"first_viewer", s.first_viewer},
          {"viewers", s.viewers},
          {"seed", s.seed}};
}

}  // namespace vts::cli
