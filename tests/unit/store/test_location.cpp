#include "vts/store/location.hpp"

#include <gtest/gtest.h>

namespace vts::store {
namespace {

TEST(Location, RemoteMeansS3HttpsOrHttpWhateverTheCase) {
  EXPECT_TRUE(is_remote("s3://b/k.pmtiles"));
  EXPECT_TRUE(is_remote("S3://b/k.pmtiles"));
  EXPECT_TRUE(is_remote("https://example.com/a.pmtiles"));
  EXPECT_TRUE(is_remote("HTTP://example.com/a.pmtiles"));
  EXPECT_FALSE(is_remote("/srv/a.pmtiles"));
  EXPECT_FALSE(is_remote("s3:/b/k"));
  EXPECT_FALSE(is_remote("file:///srv/a.pmtiles"));
  EXPECT_FALSE(is_remote("tiles/s3://x"));
}

TEST(Location, S3UrlSplitsIntoBucketAndLiteralKey) {
  Result<Location> l = parse_location("s3://my-bucket/tiles/earth 2%20.pmtiles");
  ASSERT_TRUE(l) << l.error().to_string();
  EXPECT_EQ(l->scheme, Scheme::s3);
  EXPECT_EQ(l->bucket, "my-bucket");
  EXPECT_EQ(l->key, "tiles/earth 2%20.pmtiles");  // no percent-decoding: keys are literal
  EXPECT_EQ(l->url, "s3://my-bucket/tiles/earth 2%20.pmtiles");
}

TEST(Location, S3PrefixesMayBeTheWholeBucketOrEndInASlash) {
  Result<Location> bucket = parse_location("s3://b");
  ASSERT_TRUE(bucket);
  EXPECT_EQ(bucket->bucket, "b");
  EXPECT_EQ(bucket->key, "");
  Result<Location> folder = parse_location("s3://b/sets/");
  ASSERT_TRUE(folder);
  EXPECT_EQ(folder->key, "sets/");
}

TEST(Location, MalformedLocationsAreInvalidArgumentsNamingThem) {
  for (const char* bad : {"s3://", "s3:///key", "s3://bad bucket/k", "s3://b?x/k", "https://",
                          "http:///path", "https://host/a b", "ftp://host/a", "/local/file"}) {
    Result<Location> l = parse_location(bad);
    ASSERT_FALSE(l) << bad;
    EXPECT_EQ(l.error().code, ErrorCode::invalid_argument) << bad;
    EXPECT_NE(l.error().message.find(bad), std::string::npos) << l.error().message;
  }
}

TEST(Location, HttpUrlsAreKeptAsGiven) {
  Result<Location> l = parse_location("https://cdn.example.com:8443/a/b.pmtiles?v=3");
  ASSERT_TRUE(l);
  EXPECT_EQ(l->scheme, Scheme::https);
  EXPECT_EQ(l->url, "https://cdn.example.com:8443/a/b.pmtiles?v=3");
  EXPECT_EQ(parse_location("http://127.0.0.1:80/x")->scheme, Scheme::http);
}

TEST(Location, UriEncodingKeepsOnlyUnreservedBytesAndOptionallySlashes) {
  EXPECT_EQ(uri_encode("AZaz09-._~", false), "AZaz09-._~");
  EXPECT_EQ(uri_encode("a b+c/d=é", false), "a%20b%2Bc%2Fd%3D%C3%A9");
  EXPECT_EQ(uri_encode("a b+c/d", true), "a%20b%2Bc/d");
  EXPECT_EQ(uri_encode("%", true), "%25");
}

TEST(Location, AwsEndpointUsesVirtualHostsForHostSafeBucketsAndPathsOtherwise) {
  StoreOptions o;
  o.region = "eu-west-3";
  EXPECT_EQ(s3_request_url(*parse_location("s3://tiles-1/a/b c.pmtiles"), o),
            "https://tiles-1.s3.eu-west-3.amazonaws.com/a/b%20c.pmtiles");
  // A dotted bucket would not match the endpoint's wildcard certificate; an upper-case one is
  // not a host name.
  EXPECT_EQ(s3_request_url(*parse_location("s3://my.tiles/a.pmtiles"), o),
            "https://s3.eu-west-3.amazonaws.com/my.tiles/a.pmtiles");
  EXPECT_EQ(s3_request_url(*parse_location("s3://Legacy_Bucket/a"), o),
            "https://s3.eu-west-3.amazonaws.com/Legacy_Bucket/a");
}

TEST(Location, CustomEndpointIsPathStyleUnlessVirtualHostsAreAskedFor) {
  StoreOptions o;
  o.s3_endpoint = "http://127.0.0.1:4568/";
  EXPECT_EQ(s3_request_url(*parse_location("s3://b/k/x.pmtiles"), o),
            "http://127.0.0.1:4568/b/k/x.pmtiles");
  EXPECT_EQ(s3_request_url(*parse_location("s3://b"), o), "http://127.0.0.1:4568/b");
  o.addressing = Addressing::virtual_host;
  o.s3_endpoint = "https://minio.internal:9000";
  EXPECT_EQ(s3_request_url(*parse_location("s3://b/k"), o), "https://b.minio.internal:9000/k");
  o.addressing = Addressing::path;
  o.s3_endpoint.clear();
  EXPECT_EQ(s3_request_url(*parse_location("s3://tiles/k"), o),
            "https://s3.us-east-1.amazonaws.com/tiles/k");
}

TEST(Location, KeysWithDotSegmentsAndReservedBytesStayOneCanonicalPath) {
  StoreOptions o;
  o.s3_endpoint = "http://h";
  EXPECT_EQ(s3_request_url(*parse_location("s3://b/a/../b?c#d&e"), o),
            "http://h/b/a/../b%3Fc%23d%26e");
}

}  // namespace
}  // namespace vts::store
