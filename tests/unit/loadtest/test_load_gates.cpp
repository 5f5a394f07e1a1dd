// Reading --json reports back, merging N generators' reports, gates and run-to-run comparison.
#include "vts/loadtest/load_gates.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "vts/loadtest/load_report.hpp"
#include "vts/test/temp_dir.hpp"

namespace vts::loadtest {
namespace {

using nlohmann::json;

std::vector<LatencyHistogram*> histograms(LoadReport& r) {
  return {&r.queue_time, &r.ttfb, &r.total, &r.first_visible, &r.full_resolution};
}

// A run with random latencies (recorded into `both` too, which collects the union of runs).
LoadReport random_run(std::uint32_t seed, LoadReport& both) {
  std::mt19937_64 rng(seed);
  std::lognormal_distribution<double> latency(17.0, 1.5);  // ~24 ms median, long tail
  LoadReport r;
  r.title = "generator " + std::to_string(seed);
  r.target = "http://127.0.0.1:1/earth";
  r.start = std::chrono::system_clock::time_point(std::chrono::milliseconds(1795435200000 + seed));
  r.duration_s = 3 + seed;
  r.viewers = 4;
  r.requests = 1000 + seed;
  r.errors = seed;
  r.bytes = 123456 * seed;
  r.by_status[200] = r.requests - r.errors;
  r.by_status[503] = r.errors;
  r.errors_by_kind["http_503"] = r.errors;
  r.tiers.network = r.requests;
  r.seconds.resize(seed + 1);
  for (auto& s : r.seconds) s = {100, 1000, 1, 5, 6, 7 + seed};
  auto mine = histograms(r), all = histograms(both);
  for (std::size_t k = 0; k < mine.size(); ++k) {
    for (int i = 0; i < 3000; ++i) {
      const auto v = static_cast<std::uint64_t>(latency(rng));
      mine[k]->record(v);
      all[k]->record(v);
    }
  }
  return r;
}

TEST(LoadMerge, TwoRunsReadFromJsonMergeToTheHistogramOfTheUnion) {
  LoadReport both;
  LoadReport a = random_run(1, both), b = random_run(2, both);
  auto ra = report_from_json(json::parse(to_json(a).dump()));
  auto rb = report_from_json(json::parse(to_json(b).dump()));
  ASSERT_TRUE(ra) << ra.error().message;
  ASSERT_TRUE(rb) << rb.error().message;
  auto merged = merge_reports({*ra, *rb});
  ASSERT_TRUE(merged) << merged.error().message;
  auto m = histograms(*merged), u = histograms(both);
  for (std::size_t k = 0; k < m.size(); ++k) {
    EXPECT_EQ(m[k]->count(), 6000u);
    EXPECT_EQ(m[k]->min(), u[k]->min());
    EXPECT_EQ(m[k]->max(), u[k]->max());
    EXPECT_NEAR(m[k]->mean(), u[k]->mean(), u[k]->mean() * 1e-12);
    for (double p = 0; p <= 100; p += 0.1) EXPECT_EQ(m[k]->percentile(p), u[k]->percentile(p));
    const auto mb = m[k]->buckets(), ub = u[k]->buckets();
    ASSERT_EQ(mb.size(), ub.size());
    for (std::size_t i = 0; i < mb.size(); ++i) {
      EXPECT_EQ(mb[i].low, ub[i].low);
      EXPECT_EQ(mb[i].count, ub[i].count);
    }
  }
  EXPECT_EQ(merged->requests, 2003u);
  EXPECT_EQ(merged->errors, 3u);
  EXPECT_EQ(merged->by_status[503], 3u);
  EXPECT_EQ(merged->errors_by_kind["http_503"], 3u);
  EXPECT_EQ(merged->viewers, 8u);
  EXPECT_EQ(merged->duration_s, 5);  // the longest run
  EXPECT_EQ(merged->start, a.start);
  ASSERT_EQ(merged->seconds.size(), 3u);
  EXPECT_EQ(merged->seconds[0].requests, 200u);
  EXPECT_EQ(merged->seconds[2].requests, 100u);
  EXPECT_EQ(merged->seconds[0].p99_ns, 9u);  // the highest of the runs'
}

TEST(LoadMerge, AReportReadBackWritesTheSameJson) {
  LoadReport both;
  const LoadReport a = random_run(3, both);
  json j = to_json(a);
  auto r = report_from_json(j);
  ASSERT_TRUE(r) << r.error().message;
  json k = to_json(*r);
  for (const char* h : {"queue_time", "ttfb", "total", "first_visible", "full_resolution"}) {
    EXPECT_NEAR(k["latency_ns"][h]["mean"].get<double>(), j["latency_ns"][h]["mean"].get<double>(),
                1e-6);
    k["latency_ns"][h].erase("mean");
    j["latency_ns"][h].erase("mean");
  }
  EXPECT_EQ(k, j);
}

TEST(LoadMerge, MalformedReportsAreRefusedNamingTheField) {
  LoadReport both;
  json j = to_json(random_run(1, both));
  json no_count = j;
  no_count["latency_ns"]["total"]["buckets"][0]["count"] = 0;
  auto r = report_from_json(no_count);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("latency_ns.total"), std::string::npos) << r.error().message;
  json moved = j;
  moved["latency_ns"]["ttfb"]["buckets"][0]["low"] = 3;  // not a bucket's low end
  r = report_from_json(moved);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("latency_ns.ttfb"), std::string::npos) << r.error().message;
  json no_totals = j;
  no_totals.erase("totals");
  r = report_from_json(no_totals);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("totals"), std::string::npos);
  r = report_from_json(json{{"format", 5}, {"version", "one"}});  // no exception
  ASSERT_FALSE(r);
  json old_version = j;
  old_version["version"] = "one";
  r = report_from_json(old_version);
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("version \"one\""), std::string::npos) << r.error().message;
  r = report_from_json(json{{"format", "something else"}});
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().message.find("not a vts loadtest report"), std::string::npos);
  EXPECT_FALSE(merge_reports({}));
}

void expect_refused(const Result<LoadReport>& r, const std::string& needle) {
  ASSERT_FALSE(r) << "expected an error mentioning " << needle;
  EXPECT_NE(r.error().message.find(needle), std::string::npos) << r.error().message;
}

constexpr std::uint64_t kHalf = std::uint64_t{1} << 63;

TEST(LoadMerge, BucketCountsThatSumPast64BitsAreRefused) {
  // 2^63 + 2^63 + 1 wraps to 1: the sum once agreed with a count of 1.
  auto h = LatencyHistogram::from_buckets(7, {{5, 5, kHalf}, {6, 6, kHalf}, {7, 7, 1}}, 5, 7, 6.0);
  ASSERT_FALSE(h);
  EXPECT_NE(h.error().message.find("sum past 2^64 - 1"), std::string::npos) << h.error().message;
  EXPECT_TRUE(LatencyHistogram::from_buckets(7, {{5, 5, kHalf}, {6, 6, kHalf - 1}}, 5, 6, 5.5));

  // In a report: two buckets of 2^63 and a count that matches the wrapped sum.
  LoadReport both;
  json j = to_json(random_run(1, both));
  json& total = j["latency_ns"]["total"];
  ASSERT_GE(total["buckets"].size(), 3u);
  std::uint64_t rest = 0;
  for (std::size_t i = 2; i < total["buckets"].size(); ++i)
    rest += total["buckets"][i]["count"].get<std::uint64_t>();
  total["buckets"][0]["count"] = kHalf;
  total["buckets"][1]["count"] = kHalf;
  total["count"] = rest;
  expect_refused(report_from_json(j), "latency_ns.total");
  expect_refused(report_from_json(j), "sum past 2^64 - 1");

  // Status codes that read as the same number add up, within 64 bits.
  json k = to_json(random_run(1, both));
  k["by_status"] = {{"200", kHalf}, {"0200", kHalf}};
  expect_refused(report_from_json(k), "by_status.");
}

TEST(LoadMerge, CountsWhoseSumPasses64BitsAreRefusedNamingTheFieldAndTheReport) {
  LoadReport both;
  const LoadReport a = random_run(1, both), b = random_run(2, both);
  auto refused = [&](auto&& change, const std::string& field) {
    SCOPED_TRACE(field);
    LoadReport x = a, y = b;
    change(x);
    change(y);
    auto m = merge_reports({x, y});
    expect_refused(m, field);
    expect_refused(m, "report 2 of 2");
  };
  refused([](LoadReport& r) { r.requests = kHalf; }, "totals.requests: the counts sum past 2^64");
  refused([](LoadReport& r) { r.bytes = kHalf; }, "totals.bytes");
  refused([](LoadReport& r) { r.errors = kHalf; }, "totals.errors");
  refused([](LoadReport& r) { r.camera_moves = kHalf; }, "totals.camera_moves");
  refused([](LoadReport& r) { r.cancelled = kHalf; }, "wasted.cancelled");
  refused([](LoadReport& r) { r.tiers.disk = kHalf; }, "cache_tiers.disk");
  refused([](LoadReport& r) { r.by_status[200] = kHalf; }, "by_status.200");
  refused([](LoadReport& r) { r.errors_by_kind["http_503"] = kHalf; }, "errors_by_kind.http_503");
  refused([](LoadReport& r) { r.seconds[1].bytes = kHalf; }, "seconds[1].bytes");
  refused([](LoadReport& r) { r.viewers = std::numeric_limits<std::uint32_t>::max(); },
          "scenario.viewers");
  refused([](LoadReport& r) { r.total.record(1000, kHalf); }, "latency_ns.total");
  refused([](LoadReport& r) { r.first_visible.record(1000, kHalf); }, "latency_ns.first_visible");
  // Right up to the limit is fine.
  LoadReport x = a, y = b;
  x.requests = kHalf;
  y.requests = kHalf - 1;
  auto m = merge_reports({x, y});
  ASSERT_TRUE(m) << m.error().message;
  EXPECT_EQ(m->requests, std::numeric_limits<std::uint64_t>::max());
}

TEST(LoadMerge, AReportWithMoreSecondsThanAnyRunIsRefusedNamingTheFieldAndTheFile) {
  vts::test::TempDir tmp;
  LoadReport both;
  json j = to_json(random_run(1, both));
  // A row per second of the longest run, and more: refused however small the rows are.
  j["seconds"] = json::array();
  for (std::size_t i = 0; i <= kMaxReportSeconds; ++i) j["seconds"].push_back(0);
  expect_refused(report_from_json(j), "seconds holds " + std::to_string(kMaxReportSeconds + 1) +
                                          " entries, more than " +
                                          std::to_string(kMaxReportSeconds));
  const auto file = tmp / "long.json";
  std::ofstream(file) << j.dump();
  // Refused while it is read: the parse stops at the first row too many.
  expect_refused(read_report_file(file), file.string() + ": seconds holds more than " +
                                             std::to_string(kMaxReportSeconds) + " entries");
  // So is any other array that long, even one this build does not read.
  json b = to_json(random_run(1, both));
  b["extra"] = json::array();
  for (std::size_t i = 0; i <= kMaxReportSeconds; ++i) b["extra"].push_back(0);
  std::ofstream(file) << b.dump();
  expect_refused(read_report_file(file), file.string() + ": extra holds more than");
}

TEST(LoadMerge, AReportNestedDeeperThanAnyReportIsRefusedNamingTheFile) {
  vts::test::TempDir tmp;
  LoadReport both;
  std::string text = to_json(random_run(1, both)).dump();
  text.insert(1, "\"x\": " + std::string(100000, '[') + std::string(100000, ']') + ", ");
  const auto file = tmp / "deep.json";
  std::ofstream(file) << text;
  expect_refused(read_report_file(file), file.string() + " nests objects or arrays deeper than 64");
  std::ofstream(file) << "{not json";
  expect_refused(read_report_file(file), file.string() + " is not valid JSON");
}

TEST(LoadMerge, AStartBeyondTheYear2200IsRefused) {
  LoadReport both;
  json j = to_json(random_run(1, both));
  for (const json& start :
       {json(std::numeric_limits<std::int64_t>::max()),
        json(std::numeric_limits<std::int64_t>::min()),
        json(std::numeric_limits<std::uint64_t>::max()), json(7'258'118'400'001)}) {
    j["start_unix_ms"] = start;
    expect_refused(report_from_json(j), "start_unix_ms");
  }
  j["start_unix_ms"] = 7'258'118'400'000;
  EXPECT_TRUE(report_from_json(j));
}

TEST(LatencyHistogramFromBuckets, RefusesWhatNoHistogramWrites) {
  using B = LatencyHistogram::Bucket;
  EXPECT_TRUE(LatencyHistogram::from_buckets(7, {{5, 5, 1}}, 5, 5, 5.0));
  EXPECT_FALSE(LatencyHistogram::from_buckets(7, {{5, 6, 1}}, 5, 5, 5.0));  // not a bucket
  EXPECT_FALSE(LatencyHistogram::from_buckets(7, {{6, 6, 1}, {5, 5, 1}}, 5, 6, 5.5));  // order
  EXPECT_FALSE(LatencyHistogram::from_buckets(7, {{5, 5, 1}}, 4, 5, 5.0));       // min outside
  EXPECT_FALSE(LatencyHistogram::from_buckets(0, std::vector<B>{}, 0, 0, 0.0));  // bits
}

TEST(LoadGates, ParsesSlosWithUnitsAndOperators) {
  auto g = parse_slo("p99<200ms");
  ASSERT_TRUE(g) << g.error().message;
  EXPECT_EQ(g->metric, "p99");
  EXPECT_EQ(g->op, "<");
  EXPECT_EQ(g->threshold, 200e6);
  g = parse_slo("full_res_p95 <= 1.5s");
  ASSERT_TRUE(g) << g.error().message;
  EXPECT_EQ(g->metric, "full_res_p95");
  EXPECT_EQ(g->op, "<=");
  EXPECT_EQ(g->threshold, 1.5e9);
  g = parse_slo("error_rate<2%");
  ASSERT_TRUE(g);
  EXPECT_DOUBLE_EQ(g->threshold, 0.02);
  g = parse_slo("requests_per_s>=500");
  ASSERT_TRUE(g);
  EXPECT_EQ(g->op, ">=");
  EXPECT_EQ(g->threshold, 500);
  EXPECT_TRUE(parse_slo("ttfb_p99.9<80us"));
  EXPECT_TRUE(parse_slo("first_visible_max>0ns"));
}

TEST(LoadGates, MalformedSlosNameTheTextAndListTheMetrics) {
  for (const char* bad :
       {"p99", "p99<", "p99<200", "p99<200 parsecs", "p101<1s", "latency<1s", "requests<5ms",
        "p99=200ms", "p99<-1ms", "<1s", "error_rate<5", "error_rate<200%"}) {
    auto g = parse_slo(bad);
    ASSERT_FALSE(g) << bad;
    EXPECT_EQ(g.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(g.error().message.find(std::string("'") + bad + "'"), std::string::npos)
        << g.error().message;
    EXPECT_NE(g.error().message.find("full_res_"), std::string::npos) << g.error().message;
  }
}

TEST(LoadGates, ErrorRatesAreFractionsOrPercentages) {
  EXPECT_DOUBLE_EQ(*parse_fraction("0.01"), 0.01);
  EXPECT_DOUBLE_EQ(*parse_fraction("1%"), 0.01);
  EXPECT_DOUBLE_EQ(*parse_fraction("100%"), 1.0);
  for (const char* bad : {"2", "101%", "-1%", "abc", "", "1%%", "0.5x"})
    EXPECT_FALSE(parse_fraction(bad)) << bad;
}

TEST(LoadGates, GatesHoldOrFailOnTheMeasuredValue) {
  LoadReport r;
  r.requests = 200;
  r.errors = 3;  // 1.5%
  r.duration_s = 2;
  for (int i = 1; i <= 100; ++i) r.total.record(static_cast<std::uint64_t>(i) * 1'000'000);
  std::vector<Gate> gates = {*parse_slo("p99<101ms"), *parse_slo("p99<99ms"),
                             *parse_slo("requests_per_s>=100"), max_error_rate_gate(0.01),
                             max_error_rate_gate(0.02)};
  const auto results = evaluate_gates(r, gates);
  ASSERT_EQ(results.size(), 5u);
  EXPECT_TRUE(results[0].held);
  EXPECT_FALSE(results[1].held);
  EXPECT_EQ(results[1].measured, static_cast<double>(r.total.percentile(99)));
  EXPECT_TRUE(results[2].held);
  EXPECT_FALSE(results[3].held);
  EXPECT_TRUE(results[4].held);
  const std::string line = gate_failure_line(results);
  EXPECT_EQ(line.rfind("gate failed: p99<99ms (p99 = 99", 0), 0u) << line;
  EXPECT_NE(line.find("; error_rate<=1% (error_rate = 1.5%)"), std::string::npos) << line;
  EXPECT_EQ(line.find('\n'), std::string::npos);
  const json j = gates_json(results);
  EXPECT_EQ(j[3]["held"], false);
  EXPECT_DOUBLE_EQ(j[3]["measured"].get<double>(), 0.015);
  EXPECT_EQ(gate_failure_line(evaluate_gates(r, {gates[0]})), "");
}

// Nothing measured holds no gate: moves that never reached full resolution are not in its
// histogram, so an empty one must not pass full_res_p95<1.5s as if it were 0.
TEST(LoadGates, AGateOnAnEmptyHistogramFails) {
  LoadReport r;
  r.requests = 10;
  r.duration_s = 1;
  const auto results = evaluate_gates(r, {*parse_slo("full_res_p95<1.5s"), *parse_slo("p99>1ns")});
  ASSERT_EQ(results.size(), 2u);
  EXPECT_FALSE(results[0].held);
  EXPECT_FALSE(results[1].held);
  EXPECT_TRUE(std::isnan(results[0].measured));
}

TEST(LoadCompare, MarksChangesForTheWorseBeyondTheThreshold) {
  LoadReport a, b;
  a.requests = b.requests = 1000;
  a.duration_s = 10;
  b.duration_s = 20;  // half the throughput
  b.errors = 1;       // from 0
  for (int i = 1; i <= 100; ++i) {
    a.total.record(static_cast<std::uint64_t>(i) * 1'000'000);
    b.total.record(static_cast<std::uint64_t>(i) * 1'050'000);  // 5% slower
  }
  auto changes = compare_reports(a, b, 0.1);
  auto find = [&](const char* name) {
    for (const auto& c : changes)
      if (c.name == name) return c;
    ADD_FAILURE() << name;
    return MetricChange{};
  };
  EXPECT_TRUE(find("requests_per_s").regression);
  EXPECT_DOUBLE_EQ(find("requests_per_s").relative, -0.5);
  EXPECT_TRUE(find("error_rate").regression);
  EXPECT_FALSE(find("p99").regression);
  EXPECT_NEAR(find("p99").relative, 0.05, 0.01);
  EXPECT_TRUE(compare_reports(a, b, 0.01)[6].regression);  // p99 at a 1% threshold
  const json j = compare_json(changes, 0.1);
  EXPECT_EQ(j["regressions"], 2);
  EXPECT_TRUE(j["metrics"][3]["relative"].is_null());  // error_rate from 0
  EXPECT_NE(compare_table(changes).find("REGRESSION"), std::string::npos);
}

TEST(LoadReportBaseline, TheHtmlOverlaysTheBaseline) {
  LoadReport both;
  const LoadReport a = random_run(1, both), b = random_run(2, both);
  const std::string plain = html_report(b);
  EXPECT_EQ(plain.find("baseline"), std::string::npos);
  const std::string page = html_report(b, &a);
  EXPECT_NE(page.find("id=\"plot-latency-cdf\""), std::string::npos);
  EXPECT_NE(page.find("baseline_full_resolution"), std::string::npos);
  EXPECT_NE(page.find("baseline_total"), std::string::npos);
  EXPECT_NE(page.find("class=\"compare\""), std::string::npos);
}

}  // namespace
}  // namespace vts::loadtest
