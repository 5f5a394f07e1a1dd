#include "vts/store/options.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <map>

#include "vts/test/temp_dir.hpp"

namespace vts::store {
namespace {

// An environment of our own (never the process's) with HOME at a temporary folder.
class StoreOptionsTest : public ::testing::Test {
 protected:
  StoreOptionsTest() { env_["HOME"] = home_.path().string(); }

  void write(const std::string& relative, const std::string& text) {
    const std::filesystem::path p = home_ / relative;
    std::filesystem::create_directories(p.parent_path());
    std::ofstream(p) << text;
  }
  Result<StoreOptions> resolve(const std::string& profile = {}) const {
    return StoreOptions::from_lookup(
        [this](const std::string& name) -> std::optional<std::string> {
          const auto it = env_.find(name);
          if (it == env_.end()) return std::nullopt;
          return it->second;
        },
        profile);
  }

  vts::test::TempDir home_{"vts-store-home"};
  std::map<std::string, std::string> env_;
};

TEST_F(StoreOptionsTest, NothingConfiguredMeansUnsignedRequestsToAwsUsEast1) {
  Result<StoreOptions> o = resolve();
  ASSERT_TRUE(o) << o.error().to_string();
  EXPECT_FALSE(o->credentials.has_value());
  EXPECT_EQ(o->region, "us-east-1");
  EXPECT_EQ(o->profile, "default");
  EXPECT_EQ(o->s3_endpoint, "");
  EXPECT_EQ(o->addressing, Addressing::automatic);
}

TEST_F(StoreOptionsTest, DefaultProfileOfTheSharedFilesGivesKeysRegionAndEndpoint) {
  write(".aws/credentials",
        "# comment\n[default]\naws_access_key_id = AKIDDEFAULT\n"
        "aws_secret_access_key=secret/with+chars\n\n[other]\naws_access_key_id = AKIDOTHER\n"
        "aws_secret_access_key = s2\naws_session_token = tok\n");
  write(".aws/config",
        "[default]\nregion = eu-central-1\ns3 =\n  addressing_style = path\n"
        "  endpoint_url = http://127.0.0.1:9000\n[profile other]\nregion=ap-south-1\n");
  Result<StoreOptions> o = resolve();
  ASSERT_TRUE(o) << o.error().to_string();
  ASSERT_TRUE(o->credentials);
  EXPECT_EQ(o->credentials->access_key_id, "AKIDDEFAULT");
  EXPECT_EQ(o->credentials->secret_access_key, "secret/with+chars");
  EXPECT_EQ(o->credentials->session_token, "");
  EXPECT_EQ(o->region, "eu-central-1");
  EXPECT_EQ(o->addressing, Addressing::path);
  EXPECT_EQ(o->s3_endpoint, "http://127.0.0.1:9000");
}

TEST_F(StoreOptionsTest, AwsProfileSelectsItsSectionsInBothFiles) {
  write(".aws/credentials",
        "[default]\naws_access_key_id=A\naws_secret_access_key=B\n"
        "[other]\naws_access_key_id = AKIDOTHER\naws_secret_access_key = s2\n"
        "aws_session_token = tok\n");
  write(".aws/config",
        "[default]\nregion = eu-central-1\n[profile other]\nregion=ap-south-1\n"
        "endpoint_url = https://other.example\n");
  env_["AWS_PROFILE"] = "other";
  Result<StoreOptions> o = resolve();
  ASSERT_TRUE(o) << o.error().to_string();
  EXPECT_EQ(o->profile, "other");
  EXPECT_EQ(o->credentials->access_key_id, "AKIDOTHER");
  EXPECT_EQ(o->credentials->session_token, "tok");
  EXPECT_EQ(o->region, "ap-south-1");
  EXPECT_EQ(o->s3_endpoint, "https://other.example");
  // The argument (a --profile option) beats the variable.
  Result<StoreOptions> d = resolve("default");
  ASSERT_TRUE(d);
  EXPECT_EQ(d->credentials->access_key_id, "A");
}

TEST_F(StoreOptionsTest, VariablesBeatTheFiles) {
  write(".aws/credentials", "[default]\naws_access_key_id=FILE\naws_secret_access_key=F\n");
  write(".aws/config", "[default]\nregion = eu-central-1\nendpoint_url = http://file\n");
  env_["AWS_ACCESS_KEY_ID"] = "ENV";
  env_["AWS_SECRET_ACCESS_KEY"] = "E";
  env_["AWS_SESSION_TOKEN"] = "T";
  env_["AWS_DEFAULT_REGION"] = "us-west-1";
  env_["AWS_ENDPOINT_URL"] = "http://generic";
  Result<StoreOptions> o = resolve();
  ASSERT_TRUE(o) << o.error().to_string();
  EXPECT_EQ(o->credentials->access_key_id, "ENV");
  EXPECT_EQ(o->credentials->session_token, "T");
  EXPECT_EQ(o->region, "us-west-1");
  EXPECT_EQ(o->s3_endpoint, "http://generic");
  env_["AWS_REGION"] = "us-west-2";  // AWS_REGION beats AWS_DEFAULT_REGION
  env_["AWS_ENDPOINT_URL_S3"] = "http://s3-only";
  o = resolve();
  ASSERT_TRUE(o);
  EXPECT_EQ(o->region, "us-west-2");
  EXPECT_EQ(o->s3_endpoint, "http://s3-only");
}

TEST_F(StoreOptionsTest, FileLocationsComeFromTheirVariables) {
  write("elsewhere/creds", "[default]\naws_access_key_id=X\naws_secret_access_key=Y\n");
  write("elsewhere/conf", "[default]\nregion=sa-east-1\n");
  write(".aws/credentials", "[default]\naws_access_key_id=HOME\naws_secret_access_key=H\n");
  env_["AWS_SHARED_CREDENTIALS_FILE"] = (home_ / "elsewhere/creds").string();
  env_["AWS_CONFIG_FILE"] = (home_ / "elsewhere/conf").string();
  Result<StoreOptions> o = resolve();
  ASSERT_TRUE(o) << o.error().to_string();
  EXPECT_EQ(o->credentials->access_key_id, "X");
  EXPECT_EQ(o->region, "sa-east-1");
}

TEST_F(StoreOptionsTest, CredentialsInTheConfigFileAreUsedWhenTheCredentialsFileHasNone) {
  write(".aws/config", "[profile cfg]\naws_access_key_id=C\naws_secret_access_key=D\n");
  Result<StoreOptions> o = resolve("cfg");
  ASSERT_TRUE(o) << o.error().to_string();
  EXPECT_EQ(o->credentials->access_key_id, "C");
}

TEST_F(StoreOptionsTest, AProfileNamedButNowhereIsAnErrorNamingIt) {
  write(".aws/credentials", "[default]\naws_access_key_id=A\naws_secret_access_key=B\n");
  env_["AWS_PROFILE"] = "ghost";
  Result<StoreOptions> o = resolve();
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(o.error().message.find("\"ghost\""), std::string::npos) << o.error().message;
}

TEST_F(StoreOptionsTest, HalfAKeyPairIsAnErrorNotAnUnsignedRequest) {
  env_["AWS_ACCESS_KEY_ID"] = "A";
  Result<StoreOptions> o = resolve();
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, ErrorCode::invalid_argument);
  EXPECT_NE(o.error().message.find("AWS_SECRET_ACCESS_KEY"), std::string::npos);
  env_.erase("AWS_ACCESS_KEY_ID");
  write(".aws/credentials", "[default]\naws_secret_access_key=B\n");
  o = resolve();
  ASSERT_FALSE(o);
  EXPECT_NE(o.error().message.find("credentials [default]"), std::string::npos)
      << o.error().message;
}

TEST_F(StoreOptionsTest, UnknownAddressingStyleIsRefused) {
  write(".aws/config", "[default]\ns3 =\n    addressing_style = sideways\n");
  Result<StoreOptions> o = resolve();
  ASSERT_FALSE(o);
  EXPECT_NE(o.error().message.find("sideways"), std::string::npos);
  write(".aws/config", "[default]\ns3 =\n    addressing_style = virtual\n");
  o = resolve();
  ASSERT_TRUE(o);
  EXPECT_EQ(o->addressing, Addressing::virtual_host);
}

TEST_F(StoreOptionsTest, UnreadableAndOversizedFilesAreErrorsNamingThem) {
  std::filesystem::create_directories(home_ / ".aws/credentials");  // a folder, not a file
  Result<StoreOptions> o = resolve();
  ASSERT_FALSE(o);
  EXPECT_NE(o.error().message.find(".aws/credentials"), std::string::npos) << o.error().message;
  std::filesystem::remove(home_ / ".aws/credentials");
  write(".aws/config", std::string((1 << 20) + 1, '#'));
  o = resolve();
  ASSERT_FALSE(o);
  EXPECT_EQ(o.error().code, ErrorCode::too_large);
}

TEST_F(StoreOptionsTest, EmptyVariablesCountAsUnset) {
  env_["AWS_PROFILE"] = "";
  env_["AWS_REGION"] = "";
  env_["AWS_ACCESS_KEY_ID"] = "";
  Result<StoreOptions> o = resolve();
  ASSERT_TRUE(o) << o.error().to_string();
  EXPECT_EQ(o->profile, "default");
  EXPECT_EQ(o->region, "us-east-1");
  EXPECT_FALSE(o->credentials);
}

}  // namespace
}  // namespace vts::store
