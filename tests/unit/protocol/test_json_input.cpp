// parse_json / parse_ordered_json: JSON from places we do not control is parsed with a nesting
// limit (what comes back is safe to copy, compare and dump, which recurse once per level) and,
// where asked, a limit on the entries of any one array or object; refusals name the document and
// the place, and a 100,000-level document is refused without touching the stack.
#include "vts/protocol/json_input.hpp"
#include "vts/test/nested_json.hpp"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

namespace vts {
namespace {

using test::nested_arrays;
using test::nested_objects;

void expect_refused(const Result<nlohmann::json>& r, const std::string& needle) {
  ASSERT_FALSE(r.ok()) << "expected an error mentioning " << needle;
  EXPECT_EQ(r.error().code, ErrorCode::corrupt) << r.error().to_string();
  EXPECT_NE(r.error().message.find(needle), std::string::npos) << r.error().to_string();
}

TEST(JsonInput, NestingUpToTheLimitIsAcceptedAndOneLevelMoreIsRefused) {
  for (int limit : {1, 2, 5, kMaxJsonDepth}) {
    SCOPED_TRACE(limit);
    auto ok = parse_json(nested_arrays(limit, "7"), "doc", limit);
    ASSERT_TRUE(ok.ok()) << ok.error().to_string();
    const nlohmann::json copy = *ok;  // safe to copy, compare and dump
    EXPECT_EQ(copy, *ok);
    EXPECT_EQ(copy.dump(), nested_arrays(limit, "7"));
    expect_refused(parse_json(nested_arrays(limit + 1), "doc", limit),
                   "doc nests objects or arrays deeper than " + std::to_string(limit) + " levels");
    EXPECT_TRUE(parse_json(nested_objects(limit), "doc", limit).ok());
    expect_refused(parse_json(nested_objects(limit + 1), "doc", limit), "deeper than");
  }
  // The default limit is kMaxJsonDepth; scalars need no level.
  EXPECT_TRUE(parse_json(nested_arrays(kMaxJsonDepth), "doc").ok());
  expect_refused(parse_json(nested_arrays(kMaxJsonDepth + 1), "doc"), "deeper than 64 levels");
  EXPECT_TRUE(parse_json("\"text\"", "doc", 0).ok());
  expect_refused(parse_json("[]", "doc", 0), "deeper than 0 levels");
}

TEST(JsonInput, AHundredThousandLevelsAreRefusedWithoutCrashing) {
  // 200 KB: far inside any size limit, far past any stack if copied or dumped recursively.
  expect_refused(parse_json(nested_arrays(100000), "tileset metadata"),
                 "tileset metadata nests objects or arrays deeper than 64 levels");
  expect_refused(parse_json(nested_objects(100000), "m"), "deeper than 64 levels");
  // Unbalanced too: refused at the limit, before the parser would find the missing brackets.
  expect_refused(parse_json(std::string(100000, '['), "m"), "deeper than 64 levels");
  // Also inside a document that is otherwise fine, and for ordered_json.
  const std::string doc =
      R"({"vtstream": {"width": 5, "georeference": {"x": )" + nested_arrays(100000) + "}}}";
  expect_refused(parse_json(doc, "m"), "(at vtstream.georeference.x[]x61)");
  auto ordered = parse_ordered_json(doc, "m");
  ASSERT_FALSE(ordered.ok());
  EXPECT_NE(ordered.error().message.find("deeper than 64 levels"), std::string::npos);
}

TEST(JsonInput, TheRefusalSaysWhereTheDeepValueIs) {
  auto r = parse_json(R"({"a": [{"b": [[[1]]]}]})", "doc", 4);
  expect_refused(r, "doc nests objects or arrays deeper than 4 levels (at a[].b[])");
  r = parse_json(nested_arrays(3), "doc", 2);
  expect_refused(r, "(at [][])");
  r = parse_json(R"({"a": [[[{"b": [[[[[1]]]]]}]]]})", "doc", 9);
  expect_refused(r, "(at a[][][].b[]x4)");
  // Keys are quoted short and without control characters.
  r = parse_json("{\"" + std::string(100, 'x') + "\\n\": [[1]]}", "doc", 2);
  expect_refused(r, "(at " + std::string(40, 'x') + "...[])");
  r = parse_json("{\"a\\nb\": [[1]]}", "doc", 2);
  expect_refused(r, "(at a?b[])");
}

TEST(JsonInput, InvalidJsonIsNamedWithTheParsersMessage) {
  expect_refused(parse_json("{not json", "TileJSON from http://h/t.json"),
                 "TileJSON from http://h/t.json is not valid JSON: ");
  expect_refused(parse_json("", "doc"), "doc is not valid JSON: ");
  expect_refused(parse_json("[1, 2", "doc"), "doc is not valid JSON: ");
  expect_refused(parse_json("{} trailing", "doc"), "doc is not valid JSON: ");
  expect_refused(parse_json("\"\xff\"", "doc"), "doc is not valid JSON: ");  // invalid UTF-8
  auto ok = parse_json(R"({"a": [1, 2.5, "x", null, true, {}], "b": {"c": -3}})", "doc");
  ASSERT_TRUE(ok.ok()) << ok.error().to_string();
  EXPECT_EQ((*ok)["a"].size(), 6u);
  EXPECT_EQ((*ok)["b"]["c"], -3);
  EXPECT_TRUE(parse_json("null", "doc").ok());
}

TEST(JsonInput, OrderedJsonKeepsTheDocumentsKeyOrder) {
  auto ok = parse_ordered_json(R"({"z": 1, "a": 2, "m": [3]})", "doc");
  ASSERT_TRUE(ok.ok()) << ok.error().to_string();
  EXPECT_EQ(ok->dump(), R"({"z":1,"a":2,"m":[3]})");
}

TEST(JsonInput, AnArrayOrObjectPastTheEntryLimitIsRefusedNamingIt) {
  EXPECT_TRUE(parse_json("[1,2,3]", "doc", kMaxJsonDepth, 3).ok());
  expect_refused(parse_json("[1,2,3,4]", "doc", kMaxJsonDepth, 3),
                 "doc: the top level holds more than 3 entries");
  EXPECT_TRUE(parse_json(R"({"a":1,"b":2,"c":3})", "doc", kMaxJsonDepth, 3).ok());
  expect_refused(parse_json(R"({"a":1,"b":2,"c":3,"d":4})", "doc", kMaxJsonDepth, 3),
                 "doc: the top level holds more than 3 entries");
  // Containers count as entries too, and each array counts its own.
  EXPECT_TRUE(parse_json("[[1,2,3],[4,5,6],{}]", "doc", kMaxJsonDepth, 3).ok());
  expect_refused(parse_json("[[1,2,3],[4,5,6],{},[]]", "doc", kMaxJsonDepth, 3), "more than 3");
  expect_refused(parse_json(R"({"totals": {"n": 1}, "seconds": [{}, {}, {}, {}]})", "r.json", 8, 3),
                 "r.json: seconds holds more than 3 entries");
  expect_refused(parse_json(R"({"l": {"t": {"buckets": [0, 1, 2, 3]}}})", "r.json", 8, 3),
                 "r.json: l.t.buckets holds more than 3 entries");
  expect_refused(parse_json(R"({"keys": [{"center": [1, 2, 3, 4]}]})", "r.json", 8, 3),
                 "r.json: keys[].center holds more than 3 entries");
  // The parse stops at the first entry too many: a million entries cost only the first few.
  std::string many = "[0";
  for (int i = 0; i < 1000000; ++i) many += ",0";
  many += "]";
  expect_refused(parse_json(many, "big", kMaxJsonDepth, 10), "big: the top level holds more");
  EXPECT_TRUE(parse_json(many, "big").ok());  // unlimited by default
}

}  // namespace
}  // namespace vts
