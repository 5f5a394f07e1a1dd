#include "vts/loadtest/load_report.hpp"
#include "vts/test/temp_dir.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

namespace vts::loadtest {
namespace {

namespace fs = std::filesystem;

const char* const kPlotIds[] = {"plot-latency", "plot-full-resolution", "plot-throughput",
                                "plot-errors"};

// A small run whose every figure is known.
LoadReport sample_report() {
  LoadReport r;
  r.title = "Nightly run";
  r.target = "http://127.0.0.1:8080/earth";
  r.command_line = "vts loadtest --viewers 4 http://127.0.0.1:8080/earth";
  r.start = std::chrono::system_clock::time_point(std::chrono::milliseconds(1795435200123));
  r.duration_s = 4;
  r.viewers = 4;
  r.path = "orbit";
  r.fps = 30;
  r.mode = LoopMode::open;
  r.rate = 50;
  r.requests = 200;
  r.bytes = 8'000'000;
  r.errors = 5;
  r.camera_moves = 10;
  for (int i = 0; i < 4; ++i) {
    LoadSecond s;
    s.requests = 50;
    s.bytes = 2'000'000;
    s.errors = i == 2 ? 5 : 0;
    s.p50_ns = 1'000'000 * (i + 1);
    s.p90_ns = 5'000'000 * (i + 1);
    s.p99_ns = 20'000'000 * (i + 1);
    r.seconds.push_back(s);
  }
  for (std::uint64_t i = 1; i <= 200; ++i) {
    r.queue_time.record(i * 1000);
    r.ttfb.record(i * 50'000);
    r.total.record(i * 100'000);
  }
  for (std::uint64_t i = 1; i <= 10; ++i) {
    r.first_visible.record(i * 3'000'000);
    r.full_resolution.record(i * 100'000'000);
  }
  r.tiers = {120, 30, 40, 10};
  r.by_status = {{200, 40}, {304, 10}, {503, 5}};
  r.errors_by_kind = {{"http_503", 5}};
  r.cancelled = 7;
  return r;
}

// The text of the <svg class="plot" id="ID"> element, empty when absent.
std::string plot_svg(const std::string& html, const std::string& id) {
  const std::size_t begin = html.find("<svg class=\"plot\" id=\"" + id + "\"");
  if (begin == std::string::npos) return "";
  const std::size_t end = html.find("</svg>", begin);
  return end == std::string::npos ? "" : html.substr(begin, end + 6 - begin);
}

std::size_t count(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) {
    ++n;
  }
  return n;
}

std::string read_file(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

using TempDir = vts::test::TempDir;

TEST(LoadReport, JsonCarriesTheRunScenarioAndTotals) {
  const LoadReport r = sample_report();
  const nlohmann::json j = to_json(r);
  EXPECT_EQ(j["format"], "vts-loadtest-report");
  EXPECT_EQ(j["version"], 1);
  EXPECT_EQ(j["title"], "Nightly run");
  EXPECT_EQ(j["target"], "http://127.0.0.1:8080/earth");
  EXPECT_EQ(j["command_line"], r.command_line);
  EXPECT_EQ(j["start"], "2026-11-23T12:00:00.123Z");
  EXPECT_EQ(j["start_unix_ms"], 1795435200123);
  EXPECT_EQ(j["duration_s"], 4.0);
  EXPECT_EQ(j["scenario"]["viewers"], 4);
  EXPECT_EQ(j["scenario"]["path"], "orbit");
  EXPECT_EQ(j["scenario"]["fps"], 30.0);
  EXPECT_EQ(j["scenario"]["mode"], "open");
  EXPECT_EQ(j["scenario"]["rate"], 50.0);
  EXPECT_EQ(j["scenario"]["rate_unit"], "req/s");
  EXPECT_EQ(j["totals"]["requests"], 200);
  EXPECT_EQ(j["totals"]["bytes"], 8000000);
  EXPECT_EQ(j["totals"]["errors"], 5);
  EXPECT_EQ(j["totals"]["camera_moves"], 10);
  EXPECT_DOUBLE_EQ(j["totals"]["requests_per_s"].get<double>(), 50.0);
  EXPECT_DOUBLE_EQ(j["totals"]["bytes_per_s"].get<double>(), 2e6);
  EXPECT_DOUBLE_EQ(j["totals"]["error_ratio"].get<double>(), 0.025);
  EXPECT_EQ(j["cache_tiers"],
            (nlohmann::json{{"ram", 120}, {"disk", 30}, {"network", 40}, {"revalidated", 10}}));
  EXPECT_EQ(j["by_status"], (nlohmann::json{{"200", 40}, {"304", 10}, {"503", 5}}));
  EXPECT_EQ(j["errors_by_kind"], (nlohmann::json{{"http_503", 5}}));
  EXPECT_EQ(j["wasted"], (nlohmann::json{{"cancelled", 7}}));
  ASSERT_EQ(j["seconds"].size(), 4u);
  EXPECT_EQ(j["seconds"][2], (nlohmann::json{{"t", 2},
                                             {"requests", 50},
                                             {"bytes", 2000000},
                                             {"errors", 5},
                                             {"p50_ns", 3000000},
                                             {"p90_ns", 15000000},
                                             {"p99_ns", 60000000}}));
  // What --json prints parses back to the same document.
  EXPECT_EQ(nlohmann::json::parse(j.dump()), j);
}

TEST(LoadReport, JsonHasEveryHistogramWithPercentilesAndBuckets) {
  const LoadReport r = sample_report();
  const nlohmann::json j = to_json(r)["latency_ns"];
  const std::pair<const char*, const LatencyHistogram*> expected[] = {
      {"queue_time", &r.queue_time},
      {"ttfb", &r.ttfb},
      {"total", &r.total},
      {"first_visible", &r.first_visible},
      {"full_resolution", &r.full_resolution}};
  ASSERT_EQ(j.size(), 5u);
  for (const auto& [key, h] : expected) {
    SCOPED_TRACE(key);
    ASSERT_TRUE(j.contains(key));
    const nlohmann::json& m = j[key];
    EXPECT_EQ(m["count"], h->count());
    EXPECT_EQ(m["min"], h->min());
    EXPECT_EQ(m["max"], h->max());
    EXPECT_DOUBLE_EQ(m["mean"].get<double>(), h->mean());
    EXPECT_EQ(m["p50"], h->percentile(50));
    EXPECT_EQ(m["p90"], h->percentile(90));
    EXPECT_EQ(m["p99"], h->percentile(99));
    EXPECT_EQ(m["p99_9"], h->percentile(99.9));
    EXPECT_DOUBLE_EQ(m["relative_error"].get<double>(), h->relative_error());
    EXPECT_EQ(m["sub_bucket_bits"], h->sub_bucket_bits());
    const auto buckets = h->buckets();
    ASSERT_EQ(m["buckets"].size(), buckets.size());
    std::uint64_t total = 0;
    for (std::size_t i = 0; i < buckets.size(); ++i) {
      EXPECT_EQ(m["buckets"][i]["low"], buckets[i].low);
      EXPECT_EQ(m["buckets"][i]["high"], buckets[i].high);
      EXPECT_EQ(m["buckets"][i]["count"], buckets[i].count);
      total += m["buckets"][i]["count"].get<std::uint64_t>();
    }
    EXPECT_EQ(total, h->count());
  }
  // Known values: total latency is 100 us .. 20 ms in steps of 100 us; p50 is the 100th, 10 ms.
  EXPECT_EQ(j["total"]["min"], 100000);
  EXPECT_EQ(j["total"]["max"], 20000000);
  EXPECT_GE(j["total"]["p50"].get<std::uint64_t>(), 10000000u);
  EXPECT_LE(j["total"]["p50"].get<std::uint64_t>(), 10000000u + 10000000u / 128);
  EXPECT_DOUBLE_EQ(j["total"]["mean"].get<double>(), 10050000.0);
}

TEST(LoadReport, JsonOfInvalidUtf8StringsStillDumps) {
  LoadReport r;
  r.title = "bad \xff\xfe bytes \xe2\x82";
  r.errors_by_kind = {{"a\xff", 1}, {"a\xfe", 2}};  // both become "a\uFFFD": counts add up
  const nlohmann::json j = to_json(r);
  std::string text;
  ASSERT_NO_THROW(text = j.dump());
  EXPECT_EQ(j["title"], "bad \xEF\xBF\xBD\xEF\xBF\xBD bytes \xEF\xBF\xBD");
  EXPECT_EQ(j["errors_by_kind"]["a\xEF\xBF\xBD"], 3);
  // Valid text of every length passes unchanged; overlong forms and surrogates do not.
  r.title = "Z\xC3\xBCrich \xE6\x9D\xB1\xE4\xBA\xAC \xF0\x9F\x8C\x8D";
  EXPECT_EQ(to_json(r)["title"], r.title);
  r.title = "\xC0\xAF|\xED\xA0\x80|\xF4\x90\x80\x80";
  EXPECT_EQ(to_json(r)["title"],
            "\xEF\xBF\xBD\xEF\xBF\xBD|\xEF\xBF\xBD\xEF\xBF\xBD\xEF\xBF\xBD|"
            "\xEF\xBF\xBD\xEF\xBF\xBD\xEF\xBF\xBD\xEF\xBF\xBD");
}

TEST(LoadReport, SummaryTableNamesEveryFigureInAlignedColumns) {
  const LoadReport r = sample_report();
  const std::string text = summary_table(r);
  for (const char* needle : {"Nightly run",
                             "http://127.0.0.1:8080/earth",
                             "2026-11-23 12:00:00 UTC",
                             "4.0 s",
                             "4 viewers on path \"orbit\" at 30 fps, open loop at 50 req/s",
                             "requests",
                             "200",
                             "8.00 MB",
                             "2.00 MB/s",
                             "5 (2.5%)",
                             "queue time",
                             "time to first byte",
                             "first visible tile",
                             "full resolution",
                             "p50",
                             "p90",
                             "p99",
                             "p99.9",
                             "max",
                             "mean",
                             "ram",
                             "disk",
                             "network",
                             "revalidated (304)",
                             "60.0%",
                             "HTTP status",
                             "503",
                             "http_503",
                             "cancelled"}) {
    EXPECT_NE(text.find(needle), std::string::npos) << "missing '" << needle << "' in\n" << text;
  }
  // Every table is a header, a rule and rows of the same width (numbers right-aligned), and
  // plain ASCII so that any terminal aligns it.
  std::istringstream lines(text);
  std::vector<std::string> block;
  int tables = 0;
  auto check_block = [&] {
    if (block.size() >= 2 && block[1].find_first_not_of("- ") == std::string::npos) {
      ++tables;
      for (const std::string& line : block) {
        EXPECT_EQ(line.size(), block[1].size()) << "misaligned line '" << line << "' in\n" << text;
      }
    }
    block.clear();
  };
  for (std::string line; std::getline(lines, line);) {
    if (line.empty()) {
      check_block();
    } else {
      block.push_back(line);
    }
  }
  check_block();
  EXPECT_EQ(tables, 5);
  for (char c : text) EXPECT_TRUE(c == '\n' || (c >= 0x20 && c < 0x7F)) << int(c);
  // The latency row shows the percentile in its own unit: total p50 is 10 ms (+ bucket error).
  EXPECT_NE(text.find("10.0 ms"), std::string::npos) << text;
}

TEST(LoadReport, SummaryTableNeutralisesTerminalEscapes) {
  LoadReport r = sample_report();
  r.title = "\x1b]0;owned\x07\x1b[2Jtitle";
  r.errors_by_kind = {{"\x1b[31mred", 1}};
  const std::string text = summary_table(r);
  EXPECT_EQ(text.find('\x1b'), std::string::npos);
  EXPECT_EQ(text.find('\x07'), std::string::npos);
  EXPECT_NE(text.find("title"), std::string::npos);
}

TEST(LoadReport, HtmlReportHasEveryPlotWithAxesLegendAndLines) {
  TempDir tmp;
  const LoadReport r = sample_report();
  ASSERT_TRUE(write_html_report(r, tmp.path()).ok());
  const fs::path index = tmp.path() / "index.html";
  ASSERT_TRUE(fs::exists(index));
  const std::string html = read_file(index);
  EXPECT_EQ(html, html_report(r));
  EXPECT_EQ(html.rfind("<!DOCTYPE html>", 0), 0u);
  EXPECT_NE(html.find("</html>"), std::string::npos);
  for (const char* id : kPlotIds) {
    SCOPED_TRACE(id);
    const std::string svg = plot_svg(html, id);
    ASSERT_FALSE(svg.empty());
    EXPECT_EQ(count(html, std::string("id=\"") + id + "\""), 1u);
    EXPECT_NE(svg.find("class=\"axis x-axis\""), std::string::npos);
    EXPECT_NE(svg.find("class=\"axis y-axis\""), std::string::npos);
    EXPECT_NE(svg.find("class=\"legend\""), std::string::npos);
    EXPECT_GE(count(svg, "<text"), 6u);  // tick labels, axis labels, legend
    EXPECT_GE(count(svg, "<g class=\"series\""), 1u);
    EXPECT_EQ(svg.find("no data"), std::string::npos);
  }
  // Three latency lines, two CDFs, requests and MB/s (on its own right axis), one error line.
  EXPECT_EQ(count(plot_svg(html, "plot-latency"), "<g class=\"series\""), 3u);
  EXPECT_NE(plot_svg(html, "plot-latency").find("data-series=\"p99\""), std::string::npos);
  EXPECT_EQ(count(plot_svg(html, "plot-full-resolution"), "<g class=\"series\""), 2u);
  EXPECT_EQ(count(plot_svg(html, "plot-throughput"), "<g class=\"series\""), 2u);
  EXPECT_NE(plot_svg(html, "plot-throughput").find("class=\"axis y2-axis\""), std::string::npos);
  EXPECT_EQ(count(plot_svg(html, "plot-errors"), "<g class=\"series\""), 1u);
  // The tables.
  for (const char* needle : {"Nightly run", "full resolution", "revalidated (304)", "http_503",
                             "open loop at 50 req/s", "2026-11-23 12:00:00 UTC", "p99.9"}) {
    EXPECT_NE(html.find(needle), std::string::npos) << needle;
  }
  // Self-contained: nothing is loaded from anywhere, and nothing runs.
  for (const char* banned : {"<script", " src=", " href=", "url(", "@import", "<link", "<img"}) {
    EXPECT_EQ(html.find(banned), std::string::npos) << banned;
  }
  // The rename leaves nothing temporary behind.
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(tmp.path())) names.push_back(e.path().filename());
  EXPECT_EQ(names, std::vector<std::string>{"index.html"});
}

TEST(LoadReport, ASecondWithoutRequestsBreaksTheLatencyLines) {
  LoadReport r = sample_report();
  r.seconds[1] = LoadSecond{};
  const std::string svg = plot_svg(html_report(r), "plot-latency");
  const std::size_t p50 = svg.find("data-series=\"p50\"");
  ASSERT_NE(p50, std::string::npos);
  const std::size_t d = svg.find(" d=\"", p50);
  const std::string path = svg.substr(d, svg.find('"', d + 4) - d);
  EXPECT_EQ(count(path, "M"), 2u) << path;  // second 0, then seconds 2..3
}

TEST(LoadReport, HostileStringsAreEscapedEverywhereInTheHtml) {
  LoadReport r = sample_report();
  const std::string hostile = "</title><script>alert(1)</script><img src=x onerror=alert(2)>\"'&";
  r.title = hostile;
  r.target = hostile;
  r.command_line = hostile;
  r.path = hostile;
  r.rate_unit = hostile;
  r.errors_by_kind = {{hostile, 5}};
  r.title += "\x1b\xff";
  const std::string html = html_report(r);
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_EQ(html.find("<img"), std::string::npos);
  EXPECT_EQ(count(html, "</title>"), 1u + 4u);  // the page's and each plot's own
  EXPECT_NE(html.find("&lt;/title&gt;&lt;script&gt;alert(1)&lt;/script&gt;&lt;img src=x "
                      "onerror=alert(2)&gt;&quot;&#39;&amp;"),
            std::string::npos);
  EXPECT_EQ(html.find('\x1b'), std::string::npos);
  EXPECT_EQ(html.find('\xff'), std::string::npos);
}

TEST(LoadReport, EmptyRunGivesZerosAndPlotsThatSayNoData) {
  TempDir tmp;
  const LoadReport r;  // nothing at all: no requests, no seconds, empty strings
  const nlohmann::json j = to_json(r);
  EXPECT_EQ(j["totals"]["requests"], 0);
  EXPECT_EQ(j["totals"]["requests_per_s"], 0.0);
  EXPECT_EQ(j["totals"]["error_ratio"], 0.0);
  EXPECT_EQ(j["latency_ns"]["total"]["p99"], 0);
  EXPECT_EQ(j["latency_ns"]["total"]["buckets"], nlohmann::json::array());
  EXPECT_EQ(j["seconds"], nlohmann::json::array());
  EXPECT_EQ(j["scenario"]["mode"], "closed");
  EXPECT_NO_THROW((void)j.dump());

  const std::string text = summary_table(r);
  EXPECT_NE(text.find("vts loadtest"), std::string::npos);
  EXPECT_NE(text.find("no requests completed"), std::string::npos);
  EXPECT_EQ(text.find("nan"), std::string::npos);
  EXPECT_EQ(text.find("inf"), std::string::npos);

  ASSERT_TRUE(write_html_report(r, tmp.path() / "report").ok());
  const std::string html = read_file(tmp.path() / "report" / "index.html");
  for (const char* id : kPlotIds) {
    SCOPED_TRACE(id);
    const std::string svg = plot_svg(html, id);
    ASSERT_FALSE(svg.empty());
    EXPECT_NE(svg.find("no data"), std::string::npos);
    EXPECT_EQ(svg.find("<g class=\"series\""), std::string::npos);
  }
  EXPECT_EQ(html.find("nan"), std::string::npos);
  EXPECT_NE(html.find("No requests completed"), std::string::npos);
}

TEST(LoadReport, NonFiniteFiguresShowAsZero) {
  LoadReport r = sample_report();
  r.duration_s = std::numeric_limits<double>::quiet_NaN();
  r.fps = std::numeric_limits<double>::infinity();
  r.rate = -std::numeric_limits<double>::infinity();
  const nlohmann::json j = to_json(r);
  EXPECT_EQ(j["duration_s"], 0.0);
  EXPECT_EQ(j["scenario"]["fps"], 0.0);
  EXPECT_EQ(j["scenario"]["rate"], 0.0);
  EXPECT_EQ(j["totals"]["requests_per_s"], 0.0);
  for (const std::string& text : {summary_table(r), html_report(r)}) {
    EXPECT_EQ(text.find("nan"), std::string::npos);
    EXPECT_EQ(text.find("inf"), std::string::npos);
  }
}

TEST(LoadReport, SecondsWithoutTrafficAlsoSayNoData) {
  LoadReport r;
  r.seconds.resize(5);  // the clock ran, nothing completed
  r.duration_s = 5;
  const std::string html = html_report(r);
  for (const char* id : kPlotIds) {
    EXPECT_NE(plot_svg(html, id).find("no data"), std::string::npos) << id;
  }
}

TEST(LoadReport, WriteCreatesParentsAndReplacesAnOldReport) {
  TempDir tmp;
  const fs::path dir = tmp.path() / "a" / "b";
  LoadReport r = sample_report();
  ASSERT_TRUE(write_html_report(r, dir).ok());
  r.title = "second run";
  ASSERT_TRUE(write_html_report(r, dir).ok());
  const std::string html = read_file(dir / "index.html");
  EXPECT_NE(html.find("second run"), std::string::npos);
  EXPECT_EQ(html.find("Nightly run"), std::string::npos);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator()), 1);
}

TEST(LoadReport, WriteIntoAFileFailsWithIoAndWritesNothing) {
  TempDir tmp;
  const fs::path file = tmp.path() / "not-a-folder";
  { std::ofstream(file) << "x"; }
  const Status s = write_html_report(sample_report(), file);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, ErrorCode::io);
  EXPECT_NE(s.error().message.find("not-a-folder"), std::string::npos);
  const Status below = write_html_report(sample_report(), file / "sub");
  ASSERT_FALSE(below.ok());
  EXPECT_EQ(below.error().code, ErrorCode::io);
  EXPECT_EQ(read_file(file), "x");
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp.path()), fs::directory_iterator()), 1);
}

}  // namespace
}  // namespace vts::loadtest
