// TilesetRegistry and open_tileset: loading files and folders, names, versions, hot reload.
#include "vts/server/tileset_registry.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "vts/builder/builder.hpp"
#include "vts/test/temp_dir.hpp"

namespace fs = std::filesystem;

namespace {

using RegistryTempDir = vts::test::TempDir;

void build_archive(const fs::path& out, std::uint64_t width, std::uint64_t height) {
  vts::BuildOptions o;
  o.synthetic = vts::SyntheticSpec{width, height};
  o.output = out;
  o.threads = 1;
  auto r = vts::build_synthetic_pyramid(o);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
}

void write_file(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary) << bytes;
}

bool is_lower_hex16(const std::string& s) {
  if (s.size() != 16) return false;
  for (char c : s) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  }
  return true;
}

}  // namespace

TEST(TilesetRegistry, OpensAnArchiveNamedAfterItsStemWithAHexVersionAndFileIdentity) {
  RegistryTempDir dir;
  build_archive(dir.path() / "earth.pmtiles", 600, 300);
  auto t = vts::open_tileset(dir.path() / "earth.pmtiles");
  ASSERT_TRUE(t.ok()) << t.error().to_string();
  EXPECT_EQ((*t)->name, "earth");
  EXPECT_TRUE(is_lower_hex16((*t)->version)) << (*t)->version;
  EXPECT_EQ((*t)->info.geometry.width(), 600u);
  EXPECT_EQ((*t)->file_size, fs::file_size(dir.path() / "earth.pmtiles"));
  EXPECT_NE((*t)->file_inode, 0u);
  EXPECT_NE((*t)->file_mtime_ns, 0);
}

TEST(TilesetRegistry, VersionIsStableForTheSameBytesAndDiffersForADifferentArchive) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 600, 300);
  build_archive(dir.path() / "b.pmtiles", 500, 300);
  auto a1 = vts::open_tileset(dir.path() / "a.pmtiles");
  auto a2 = vts::open_tileset(dir.path() / "a.pmtiles");
  auto b = vts::open_tileset(dir.path() / "b.pmtiles");
  ASSERT_TRUE(a1.ok() && a2.ok() && b.ok());
  EXPECT_EQ((*a1)->version, (*a2)->version);
  EXPECT_NE((*a1)->version, (*b)->version);
}

TEST(TilesetRegistry, RefusesFileNamesThatAreNotValidTilesetNames) {
  RegistryTempDir dir;
  for (const char* name : {".hidden.pmtiles", "with space.pmtiles", "caf\xc3\xa9.pmtiles"}) {
    build_archive(dir.path() / name, 300, 200);
    auto t = vts::open_tileset(dir.path() / name);
    ASSERT_FALSE(t.ok()) << name;
    EXPECT_EQ(t.error().code, vts::ErrorCode::invalid_argument);
    EXPECT_NE(t.error().message.find("tileset name"), std::string::npos) << t.error().message;
  }
  const std::string long_name(129, 'a');
  build_archive(dir.path() / (long_name + ".pmtiles"), 300, 200);
  EXPECT_FALSE(vts::open_tileset(dir.path() / (long_name + ".pmtiles")).ok());
}

TEST(TilesetRegistry, RefusesAFileThatIsNotAnArchive) {
  RegistryTempDir dir;
  write_file(dir.path() / "junk.pmtiles", "not an archive at all");
  auto t = vts::open_tileset(dir.path() / "junk.pmtiles");
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.error().message.find("junk.pmtiles"), std::string::npos) << t.error().message;
}

TEST(TilesetRegistry, LoadsEveryArchiveOfAFolderButNotOtherFilesOrSubfolders) {
  RegistryTempDir dir;
  build_archive(dir.path() / "b.pmtiles", 300, 200);
  build_archive(dir.path() / "a.pmtiles", 300, 200);
  write_file(dir.path() / "notes.txt", "hello");
  fs::create_directories(dir.path() / "sub");
  build_archive(dir.path() / "sub" / "c.pmtiles", 300, 200);

  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  ASSERT_EQ(registry.size(), 2u);
  auto all = registry.all();
  EXPECT_EQ(all[0]->name, "a");
  EXPECT_EQ(all[1]->name, "b");
  EXPECT_NE(registry.find(std::string_view("b")), nullptr);
  EXPECT_EQ(registry.find("c"), nullptr);
  EXPECT_EQ(registry.find(""), nullptr);
}

TEST(TilesetRegistry, LoadsFilesAndFoldersTogether) {
  RegistryTempDir dir;
  fs::create_directories(dir.path() / "f");
  build_archive(dir.path() / "f" / "one.pmtiles", 300, 200);
  build_archive(dir.path() / "two.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path() / "f", dir.path() / "two.pmtiles"}).ok());
  EXPECT_EQ(registry.size(), 2u);
}

TEST(TilesetRegistry, LoadFailsNamingAPathThatDoesNotExist) {
  RegistryTempDir dir;
  vts::TilesetRegistry registry;
  auto s = registry.load({dir.path() / "missing.pmtiles"});
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, vts::ErrorCode::not_found);
  EXPECT_NE(s.error().message.find("missing.pmtiles"), std::string::npos);
}

TEST(TilesetRegistry, LoadFailsNamingAFolderWithoutArchives) {
  RegistryTempDir dir;
  vts::TilesetRegistry registry;
  auto s = registry.load({dir.path()});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find(dir.path().string()), std::string::npos) << s.error().message;
}

TEST(TilesetRegistry, LoadRefusesDuplicateNamedFilesAndChangesNothing) {
  RegistryTempDir dir;
  fs::create_directories(dir.path() / "x");
  fs::create_directories(dir.path() / "y");
  build_archive(dir.path() / "x" / "same.pmtiles", 300, 200);
  build_archive(dir.path() / "y" / "same.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  auto s = registry.load({dir.path() / "x" / "same.pmtiles", dir.path() / "y" / "same.pmtiles"});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().message.find("duplicate tileset name \"same\""), std::string::npos);
  EXPECT_EQ(registry.size(), 0u);

  ASSERT_TRUE(registry.load({dir.path() / "x"}).ok());
  EXPECT_FALSE(registry.load({dir.path() / "y" / "same.pmtiles"}).ok());
  EXPECT_EQ(registry.size(), 1u);
}

// A folder's archive whose name is taken is skipped, as a reload skips it: the first path wins.
TEST(TilesetRegistry, LoadSkipsAFolderArchiveWhoseNameIsTaken) {
  RegistryTempDir dir;
  fs::create_directories(dir.path() / "x");
  fs::create_directories(dir.path() / "y");
  build_archive(dir.path() / "x" / "same.pmtiles", 300, 200);
  build_archive(dir.path() / "y" / "same.pmtiles", 600, 300);
  build_archive(dir.path() / "y" / "other.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  auto s = registry.load({dir.path() / "x", dir.path() / "y"});
  ASSERT_TRUE(s.ok()) << s.error().to_string();
  EXPECT_EQ(registry.size(), 2u);
  EXPECT_EQ(registry.find("same")->info.geometry.width(), 300u);
  const auto skipped = registry.skipped();
  ASSERT_EQ(skipped.size(), 1u);
  EXPECT_EQ(skipped[0].file, dir.path() / "y" / "same.pmtiles");
  EXPECT_EQ(skipped[0].error.code, vts::ErrorCode::invalid_argument);
  EXPECT_NE(
      skipped[0].error.message.find("taken by " + (dir.path() / "x" / "same.pmtiles").string()),
      std::string::npos)
      << skipped[0].error.message;
}

// A half-copied archive or a file with an impossible name in a served folder must not keep the
// others offline: they are skipped, each with its reason, exactly as a reload would skip them.
TEST(TilesetRegistry, LoadServesAFolderWithoutItsBrokenOrBadlyNamedArchivesAndListsThem) {
  RegistryTempDir dir;
  build_archive(dir.path() / "good.pmtiles", 600, 300);
  const auto size = fs::file_size(dir.path() / "good.pmtiles");
  fs::copy_file(dir.path() / "good.pmtiles", dir.path() / "half.pmtiles");
  fs::resize_file(dir.path() / "half.pmtiles", size / 2);
  fs::copy_file(dir.path() / "good.pmtiles", dir.path() / "caf\xc3\xa9.pmtiles");

  vts::TilesetRegistry registry;
  auto s = registry.load({dir.path()});
  ASSERT_TRUE(s.ok()) << s.error().to_string();
  EXPECT_EQ(registry.size(), 1u);
  EXPECT_NE(registry.find("good"), nullptr);
  const auto skipped = registry.skipped();
  ASSERT_EQ(skipped.size(), 2u);
  // Sorted by file: "caf\xc3\xa9" < "half".
  EXPECT_EQ(skipped[0].file, dir.path() / "caf\xc3\xa9.pmtiles");
  EXPECT_EQ(skipped[0].error.code, vts::ErrorCode::invalid_argument);
  EXPECT_NE(skipped[0].error.message.find("tileset name"), std::string::npos);
  EXPECT_EQ(skipped[1].file, dir.path() / "half.pmtiles");
  EXPECT_EQ(vts::exit_code(skipped[1].error.code), 5) << skipped[1].error.to_string();
  for (const auto& k : skipped)  // the reason does not repeat the file: a listing names it
    EXPECT_EQ(k.error.message.find(dir.path().string()), std::string::npos) << k.error.message;

  // Not retried while they stay as they are; listed until they change.
  auto r = registry.reload(false);
  EXPECT_TRUE(r.failures.empty());
  EXPECT_EQ(registry.skipped().size(), 2u);
  // The half copy completed (renamed over it): served, and no longer listed.
  fs::copy_file(dir.path() / "good.pmtiles", dir.path() / "half.tmp");
  fs::rename(dir.path() / "half.tmp", dir.path() / "half.pmtiles");
  r = registry.reload(false);
  EXPECT_EQ(r.added, 1);
  EXPECT_NE(registry.find("half"), nullptr);
  ASSERT_EQ(registry.skipped().size(), 1u);
  // The badly named one removed: forgotten.
  fs::remove(dir.path() / "caf\xc3\xa9.pmtiles");
  r = registry.reload(false);
  EXPECT_TRUE(registry.skipped().empty());
}

TEST(TilesetRegistry, LoadStillFailsOnABrokenArchiveItWasNamed) {
  RegistryTempDir dir;
  build_archive(dir.path() / "good.pmtiles", 300, 200);
  fs::copy_file(dir.path() / "good.pmtiles", dir.path() / "half.pmtiles");
  fs::resize_file(dir.path() / "half.pmtiles", fs::file_size(dir.path() / "good.pmtiles") / 2);
  vts::TilesetRegistry registry;
  auto s = registry.load({dir.path() / "good.pmtiles", dir.path() / "half.pmtiles"});
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(vts::exit_code(s.error().code), 5);
  EXPECT_NE(s.error().message.find("half.pmtiles"), std::string::npos) << s.error().message;
  EXPECT_EQ(registry.size(), 0u);
  EXPECT_TRUE(registry.skipped().empty());
}

// Nothing to serve is a failure, as a folder without archives is; the message lists each file.
TEST(TilesetRegistry, LoadFailsWhenEveryArchiveFoundIsRefused) {
  RegistryTempDir dir;
  write_file(dir.path() / "junk.pmtiles", "not an archive at all");
  build_archive(dir.path() / "caf\xc3\xa9.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  auto s = registry.load({dir.path()});
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().code, vts::ErrorCode::invalid_argument) << "the first file's code";
  EXPECT_NE(s.error().message.find("no archive can be served"), std::string::npos);
  EXPECT_NE(s.error().message.find("junk.pmtiles: "), std::string::npos) << s.error().message;
  EXPECT_NE(s.error().message.find("caf\xc3\xa9.pmtiles: tileset name"), std::string::npos)
      << s.error().message;
  EXPECT_EQ(registry.size(), 0u);
}

// A file name in a served folder is not trusted to be one line: in the error that lists the
// refused archives, a newline in a name cannot start a line of its own and ESC cannot reach a
// terminal; both appear as \xHH (escape_controls).
TEST(TilesetRegistry, LoadFailsListingRefusedArchivesOneLineEachWhateverTheirNames) {
  RegistryTempDir dir;
  const std::string crafted = "x\nvts serve: forged line \x1b[2J.pmtiles";
  write_file(dir.path() / crafted, "not an archive at all");
  vts::TilesetRegistry registry;
  auto s = registry.load({dir.path()});
  ASSERT_FALSE(s.ok());
  const std::string& m = s.error().message;
  EXPECT_EQ(m.find('\x1b'), std::string::npos) << m;
  EXPECT_EQ(std::count(m.begin(), m.end(), '\n'), 1) << "the header line, then one per file: " << m;
  EXPECT_NE(m.find("x\\x0avts serve: forged line \\x1b[2J.pmtiles: "), std::string::npos) << m;
}

TEST(TilesetRegistry, ReloadListsTheArchivesItRefusesAsSkipped) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  EXPECT_TRUE(registry.skipped().empty());
  write_file(dir.path() / "junk.pmtiles", std::string(4096, 'x'));
  write_file(dir.path() / "garbage.tmp", std::string(4096, 'x'));
  fs::rename(dir.path() / "garbage.tmp", dir.path() / "a.pmtiles");
  auto r = registry.reload(false);
  EXPECT_EQ(r.failures.size(), 2u);
  const auto skipped = registry.skipped();
  ASSERT_EQ(skipped.size(), 2u);
  EXPECT_EQ(skipped[0].file, dir.path() / "a.pmtiles");
  EXPECT_NE(skipped[0].error.message.find("keeps the previous one"), std::string::npos)
      << skipped[0].error.message;
  EXPECT_EQ(skipped[1].file, dir.path() / "junk.pmtiles");
  EXPECT_NE(registry.find("a"), nullptr);
}

TEST(TilesetRegistry, ReloadWithoutChangesSwapsNothingAndForceReopensAll) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 300, 200);
  build_archive(dir.path() / "b.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  auto before = registry.find("a");
  auto r = registry.reload(false);
  EXPECT_EQ(r.swapped, 0);
  EXPECT_TRUE(r.failures.empty());
  EXPECT_EQ(registry.find("a"), before);

  auto forced = registry.reload(true);
  EXPECT_EQ(forced.swapped, 2);
  EXPECT_NE(registry.find("a"), before);
  EXPECT_EQ(registry.find("a")->version, before->version);
}

TEST(TilesetRegistry, ReloadSwapsInAReplacedArchiveWhileTheOldSnapshotStaysReadable) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 600, 300);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path() / "a.pmtiles"}).ok());
  auto old = registry.find("a");
  const auto old_tile = old->reader->get(vts::TileId{0, 0, 0});
  ASSERT_TRUE(old_tile.ok());
  const std::vector<std::uint8_t> old_bytes(old_tile->begin(), old_tile->end());

  // The builder writes under a temporary name and renames over the destination.
  fs::create_directories(dir.path() / "staging");
  build_archive(dir.path() / "staging" / "a.pmtiles", 500, 250);
  fs::rename(dir.path() / "staging" / "a.pmtiles", dir.path() / "a.pmtiles");

  auto r = registry.reload(false);
  EXPECT_EQ(r.swapped, 1);
  EXPECT_TRUE(r.failures.empty());
  auto fresh = registry.find("a");
  EXPECT_NE(fresh->version, old->version);
  EXPECT_EQ(fresh->info.geometry.width(), 500u);

  // A request in flight still holds the old mapping, byte for byte.
  const auto again = old->reader->get(vts::TileId{0, 0, 0});
  ASSERT_TRUE(again.ok());
  EXPECT_TRUE(std::equal(again->begin(), again->end(), old_bytes.begin(), old_bytes.end()));
}

// A copy over the served file (same inode) may pause with b's header and directories over a's
// tile bytes: it is opened only once it has been left unmodified for `settle`.
TEST(TilesetRegistry, ReloadWaitsForAFileModifiedInPlaceToSettle) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 600, 300);
  build_archive(dir.path() / "b.pmtiles.tmp", 500, 250);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path() / "a.pmtiles"}).ok());
  auto old = registry.find("a");
  const auto inode = old->file_inode;
  fs::copy_file(dir.path() / "b.pmtiles.tmp", dir.path() / "a.pmtiles",
                fs::copy_options::overwrite_existing);
  ASSERT_EQ(fs::hard_link_count(dir.path() / "a.pmtiles"), 1u);

  auto r = registry.reload(false, std::chrono::hours(1));
  EXPECT_EQ(r.swapped, 0);
  EXPECT_EQ(r.settling, 1);
  EXPECT_TRUE(r.failures.empty());
  EXPECT_EQ(registry.find("a"), old);
  const auto changed = old->reader->get(vts::TileId{0, 0, 0});
  ASSERT_FALSE(changed.ok());
  EXPECT_EQ(changed.error().code, vts::ErrorCode::changed);

  // Left alone for longer than `settle` (its modification time two hours back): swapped in.
  struct stat st {};
  ASSERT_EQ(::stat((dir.path() / "a.pmtiles").c_str(), &st), 0);
  ASSERT_EQ(static_cast<std::uint64_t>(st.st_ino), inode) << "the copy did not write in place";
  const timespec past[2] = {{st.st_atim.tv_sec - 7200, 0}, {st.st_mtim.tv_sec - 7200, 0}};
  ASSERT_EQ(::utimensat(AT_FDCWD, (dir.path() / "a.pmtiles").c_str(), past, 0), 0);
  r = registry.reload(false, std::chrono::hours(1));
  EXPECT_EQ(r.swapped, 1);
  EXPECT_EQ(r.settling, 0);
  EXPECT_EQ(registry.find("a")->info.geometry.width(), 500u);
}

// A file renamed over the served one is complete: no settling.
TEST(TilesetRegistry, ReloadSwapsARenamedReplacementAtOnceWhateverTheSettleTime) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 600, 300);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path() / "a.pmtiles"}).ok());
  build_archive(dir.path() / "b.tmp", 500, 250);
  fs::rename(dir.path() / "b.tmp", dir.path() / "a.pmtiles");
  const auto r = registry.reload(false, std::chrono::hours(1));
  EXPECT_EQ(r.swapped, 1);
  EXPECT_EQ(r.settling, 0);
}

TEST(TilesetRegistry, ReloadRefusesABrokenReplacementAndKeepsServingTheOldArchive) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 600, 300);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  auto old = registry.find("a");

  write_file(dir.path() / "garbage.tmp", std::string(4096, 'x'));
  fs::rename(dir.path() / "garbage.tmp", dir.path() / "a.pmtiles");
  auto r = registry.reload(false);
  EXPECT_EQ(r.swapped, 0);
  ASSERT_EQ(r.failures.size(), 1u);
  EXPECT_NE(r.failures[0].message.find("refused"), std::string::npos) << r.failures[0].message;
  EXPECT_EQ(registry.find("a"), old);
  EXPECT_TRUE(old->reader->get(vts::TileId{0, 0, 0}).ok());
}

TEST(TilesetRegistry, ReloadReportsADeletedArchiveLoadedByNameAndKeepsIt) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path() / "a.pmtiles"}).ok());
  fs::remove(dir.path() / "a.pmtiles");
  auto r = registry.reload(false);
  EXPECT_EQ(r.swapped, 0);
  EXPECT_EQ(r.removed, 0);
  EXPECT_EQ(r.failures.size(), 1u);
  ASSERT_NE(registry.find("a"), nullptr);
  EXPECT_TRUE(registry.find("a")->reader->get(vts::TileId{0, 0, 0}).ok());
}

TEST(TilesetRegistry, ReloadAddsArchivesThatAppearInAFolderAndRemovesThoseThatLeave) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  auto a = registry.find("a");
  ASSERT_NE(a, nullptr);

  build_archive(dir.path() / "b.pmtiles", 600, 300);
  auto r = registry.reload(false);
  EXPECT_EQ(r.added, 1);
  EXPECT_TRUE(r.failures.empty());
  ASSERT_NE(registry.find("b"), nullptr);
  EXPECT_EQ(registry.find("b")->info.geometry.width(), 600u);

  fs::remove(dir.path() / "a.pmtiles");
  r = registry.reload(false);
  EXPECT_EQ(r.removed, 1);
  EXPECT_TRUE(r.failures.empty());
  EXPECT_EQ(registry.find("a"), nullptr);
  EXPECT_EQ(registry.size(), 1u);
  // A request that took its snapshot before the removal still reads the old mapping.
  EXPECT_TRUE(a->reader->get(vts::TileId{0, 0, 0}).ok());
  // Nothing changed since: nothing happens.
  r = registry.reload(false);
  EXPECT_EQ(r.added + r.removed + r.swapped, 0);
}

TEST(TilesetRegistry, ReloadRefusesABrokenNewArchiveOnceUntilItsFileChanges) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  write_file(dir.path() / "junk.tmp", std::string(4096, 'x'));
  fs::rename(dir.path() / "junk.tmp", dir.path() / "junk.pmtiles");
  auto r = registry.reload(false);
  EXPECT_EQ(r.added, 0);
  ASSERT_EQ(r.failures.size(), 1u);
  EXPECT_NE(r.failures[0].message.find("junk.pmtiles"), std::string::npos);
  // Not retried (nor reported again) while the file stays as it is...
  r = registry.reload(false);
  EXPECT_TRUE(r.failures.empty());
  EXPECT_EQ(registry.find("junk"), nullptr);
  // ... but a valid archive put in its place is served.
  build_archive(dir.path() / "junk.tmp", 300, 200);
  fs::rename(dir.path() / "junk.tmp", dir.path() / "junk.pmtiles");
  r = registry.reload(false);
  EXPECT_EQ(r.added, 1);
  EXPECT_NE(registry.find("junk"), nullptr);
}

TEST(TilesetRegistry, ReloadRefusesANewArchiveWhoseNameIsTaken) {
  RegistryTempDir dir;
  fs::create_directories(dir.path() / "f");
  build_archive(dir.path() / "a.pmtiles", 300, 200);
  build_archive(dir.path() / "f" / "b.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path() / "a.pmtiles", dir.path() / "f"}).ok());
  build_archive(dir.path() / "f" / "a.pmtiles", 600, 300);
  auto r = registry.reload(false);
  EXPECT_EQ(r.added, 0);
  ASSERT_EQ(r.failures.size(), 1u);
  EXPECT_NE(r.failures[0].message.find("duplicate tileset name"), std::string::npos);
  EXPECT_EQ(registry.find("a")->info.geometry.width(), 300u);
}

TEST(TilesetRegistry, LookupsDuringReloadAlwaysSeeACompleteReadableTileset) {
  RegistryTempDir dir;
  build_archive(dir.path() / "a.pmtiles", 300, 200);
  vts::TilesetRegistry registry;
  ASSERT_TRUE(registry.load({dir.path()}).ok());
  std::atomic<bool> stop{false};
  std::thread reloader([&] {
    for (int i = 0; i < 20; ++i) EXPECT_EQ(registry.reload(true).swapped, 1);
    stop = true;
  });
  int lookups = 0;
  while (!stop || lookups == 0) {
    auto t = registry.find("a");
    ASSERT_NE(t, nullptr);
    ASSERT_TRUE(t->reader->get(vts::TileId{0, 0, 0}).ok());
    ++lookups;
  }
  reloader.join();
  EXPECT_GT(lookups, 0);
}
