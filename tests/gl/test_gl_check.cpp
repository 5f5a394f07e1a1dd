// The debug GL checks and the GL handles. This file turns the checks on whatever the build type,
// so the release build tests them too.
#define VTS_GL_CHECKS 1
#include "vts/renderer/gl_check.hpp"

#include <epoxy/gl.h>
#include <gtest/gtest.h>

#include <string>
#include <thread>
#include <vector>

#include "gl_fixture.hpp"
#include "vts/renderer/gl_handle.hpp"

using namespace vts::renderer;

namespace {

std::vector<std::string>* g_reports = nullptr;
void collect(const std::string& m) {
  g_reports->push_back(m);
}

class GlCheckTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string error;
    ASSERT_NE(vts::test::shared_gl_context(&error), nullptr) << error;
    gl_check::set_gl_thread();
    while (glGetError() != GL_NO_ERROR) {
    }
    g_reports = &reports_;
    previous_ = gl_check::set_reporter(collect);
  }
  void TearDown() override {
    gl_check::set_reporter(previous_);
    g_reports = nullptr;
  }
  std::vector<std::string> reports_;
  gl_check::Reporter previous_ = nullptr;
};

void invalid_enable() {
  VTS_GL_CALL_SITE("invalid_enable");
  glEnable(0x7fff);  // no such capability: GL_INVALID_ENUM
}

TEST_F(GlCheckTest, AnErrorRaisedInACallSiteIsReportedWithItsNameFileAndLine) {
  invalid_enable();
  ASSERT_EQ(reports_.size(), 1u);
  EXPECT_NE(reports_[0].find("invalid_enable (" __FILE__ ":"), std::string::npos) << reports_[0];
  EXPECT_NE(reports_[0].find("GL_INVALID_ENUM (0x0500) raised in it"), std::string::npos)
      << reports_[0];
  EXPECT_EQ(glGetError(), GL_NO_ERROR);  // the check read it
}

TEST_F(GlCheckTest, AnErrorLeftByTheCallerIsReportedAsRaisedBefore) {
  glEnable(0x7fff);
  { VTS_GL_CALL_SITE("clean"); }
  ASSERT_EQ(reports_.size(), 1u);
  EXPECT_NE(reports_[0].find("raised before it"), std::string::npos) << reports_[0];
}

TEST_F(GlCheckTest, ACleanCallSiteReportsNothing) {
  {
    VTS_GL_CALL_SITE("clean");
    glEnable(GL_BLEND);
    glDisable(GL_BLEND);
  }
  EXPECT_TRUE(reports_.empty());
}

TEST(GlCheckDeathTest, AGlEntryPointOnAnotherThreadAborts) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_DEATH(
      {
        gl_check::set_gl_thread();
        std::thread t([] { gl_check::assert_gl_thread("VirtualTexture::render"); });
        t.join();
      },
      "VirtualTexture::render: called on thread .*, not the GL thread");
}

TEST_F(GlCheckTest, HandlesDeleteTheirObjectAndMoveOwnership) {
  GlTexture a;
  glCreateTextures(GL_TEXTURE_2D, 1, a.out());
  const unsigned name = a.get();
  ASSERT_NE(name, 0u);
  EXPECT_TRUE(glIsTexture(name));
  GlTexture b = std::move(a);
  EXPECT_EQ(a.get(), 0u);
  EXPECT_EQ(b.get(), name);
  EXPECT_TRUE(glIsTexture(name));
  b.reset();
  EXPECT_FALSE(glIsTexture(name));
  {
    GlBuffer buffer;
    glCreateBuffers(1, buffer.out());
    EXPECT_TRUE(glIsBuffer(buffer.get()));
    GlBuffer other;
    glCreateBuffers(1, other.out());
    const unsigned first = buffer.get();
    buffer = std::move(other);  // the first buffer goes
    EXPECT_FALSE(glIsBuffer(first));
  }
  EXPECT_EQ(glGetError(), GL_NO_ERROR);
}

}  // namespace
