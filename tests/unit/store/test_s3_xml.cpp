// White-box tests of the store's XML reader (store/src/s3_xml.hpp) on S3's documents and on
// hostile ones.
#include "s3_xml.hpp"

#include <gtest/gtest.h>

namespace vts::store::detail {
namespace {

constexpr const char* kListPage = R"(<?xml version="1.0" encoding="UTF-8"?>
<ListBucketResult xmlns="http://s3.amazonaws.com/doc/2006-03-01/">
  <Name>b</Name><Prefix>sets/</Prefix><KeyCount>2</KeyCount><IsTruncated>true</IsTruncated>
  <NextContinuationToken>1ueGcxLPRx1Tr/XYExHnhbYLgveDs2J/wm36Hy4vbOwM=</NextContinuationToken>
  <Contents><Key>sets/a &amp; b.pmtiles</Key><Size>1234</Size>
    <ETag>&quot;9b2cf535f27731c974343645a3985328&quot;</ETag></Contents>
  <Contents><Key>sets/c.pmtiles</Key><Size>5</Size><ETag>"x"</ETag></Contents>
  <CommonPrefixes><Prefix>sets/deeper/</Prefix></CommonPrefixes>
</ListBucketResult>)";

TEST(S3Xml, ListPageGivesKeysSizesETagsAndTheContinuationToken) {
  Result<XmlNode> doc = parse_xml(kListPage);
  ASSERT_TRUE(doc) << doc.error().to_string();
  EXPECT_EQ(doc->name, "ListBucketResult");
  EXPECT_EQ(doc->child_text("IsTruncated"), "true");
  EXPECT_EQ(doc->child_text("NextContinuationToken"),
            "1ueGcxLPRx1Tr/XYExHnhbYLgveDs2J/wm36Hy4vbOwM=");
  std::vector<const XmlNode*> contents;
  for (const XmlNode& c : doc->children) {
    if (c.name == "Contents") contents.push_back(&c);
  }
  ASSERT_EQ(contents.size(), 2u);
  EXPECT_EQ(contents[0]->child_text("Key"), "sets/a & b.pmtiles");
  EXPECT_EQ(contents[0]->child_text("Size"), "1234");
  EXPECT_EQ(contents[0]->child_text("ETag"), "\"9b2cf535f27731c974343645a3985328\"");
  EXPECT_EQ(doc->child("CommonPrefixes")->child_text("Prefix"), "sets/deeper/");
  EXPECT_EQ(doc->child("Missing"), nullptr);
  EXPECT_EQ(doc->child_text("Missing"), "");
}

TEST(S3Xml, ErrorDocumentGivesCodeAndMessage) {
  const char* body =
      "<?xml version=\"1.0\"?><Error><Code>NoSuchKey</Code>"
      "<Message>The specified key does not exist.</Message><Key>k</Key></Error>";
  EXPECT_EQ(s3_error_code(body), "NoSuchKey");
  EXPECT_EQ(s3_error_text(body), "NoSuchKey: The specified key does not exist.");
  EXPECT_EQ(s3_error_text("<html><body>503</body></html>"), "");
  EXPECT_EQ(s3_error_text("not xml at all"), "");
  EXPECT_EQ(s3_error_text(""), "");
}

TEST(S3Xml, PrefixedNamesAreReadByTheirLocalName) {
  Result<XmlNode> doc = parse_xml("<s3:Error xmlns:s3=\"u\"><s3:Code>X</s3:Code></s3:Error>");
  ASSERT_TRUE(doc);
  EXPECT_EQ(doc->name, "Error");
  EXPECT_EQ(doc->child_text("Code"), "X");
}

TEST(S3Xml, EntityExpansionIsRefusedBeforeAnyExpands) {
  const char* laughs = R"(<?xml version="1.0"?>
<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
<!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">]>
<Error><Code>&lol3;</Code></Error>)";
  Result<XmlNode> doc = parse_xml(laughs);
  ASSERT_FALSE(doc);
  EXPECT_EQ(doc.error().code, ErrorCode::corrupt);
  EXPECT_NE(doc.error().message.find("document type"), std::string::npos) << doc.error().message;
  EXPECT_EQ(s3_error_text(laughs), "");
}

TEST(S3Xml, DeepNestingIsRefused) {
  std::string deep;
  for (int i = 0; i < 100; ++i) deep += "<a>";
  for (int i = 0; i < 100; ++i) deep += "</a>";
  Result<XmlNode> doc = parse_xml(deep);
  ASSERT_FALSE(doc);
  EXPECT_NE(doc.error().message.find("too deep"), std::string::npos);
  std::string ok;
  for (int i = 0; i < 60; ++i) ok += "<a>";
  for (int i = 0; i < 60; ++i) ok += "</a>";
  EXPECT_TRUE(parse_xml(ok));
}

TEST(S3Xml, EveryTruncationOfAListPageIsCorruptNotACrash) {
  const std::string page = kListPage;
  for (std::size_t n = 0; n < page.size(); ++n) {
    Result<XmlNode> doc = parse_xml(std::string_view(page).substr(0, n));
    ASSERT_FALSE(doc) << "a prefix of " << n << " bytes parsed";
    EXPECT_EQ(doc.error().code, ErrorCode::corrupt);
  }
  EXPECT_TRUE(parse_xml(page));
}

}  // namespace
}  // namespace vts::store::detail
