// The streaming policy the GL viewer and the load tester share, with the clock in the test's hand.
#include "vts/renderer/tile_stream.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace vts::renderer {
namespace {

using namespace std::chrono_literals;
using Clock = TileStream::Clock;

const TileId kStreamRoot{0, 0, 0};
const TileId kA{1, 0, 0}, kB{1, 1, 0}, kC{2, 0, 0}, kD{2, 3, 1};

std::vector<TileRequest> want(std::initializer_list<TileId> tiles) {
  std::vector<TileRequest> out;
  for (const TileId t : tiles) out.push_back(TileRequest{t, 1, true});
  return out;
}

std::vector<TileId> tiles_of(const std::vector<TileRequest>& requests) {
  std::vector<TileId> out;
  for (const auto& r : requests) out.push_back(r.tile);
  return out;
}

// A stream whose every decision is written down, as "kind z/x/y".
struct Traced {
  std::vector<std::string> log;
  TileStream stream;
  explicit Traced(SlotCache::Options slots = {.capacity = 8, .keep_frames = 1})
      : stream(TileStreamOptions{.slots = slots, .trace = [this](const StreamEvent& e) {
                                   log.push_back(std::string(stream_event_name(e.kind)) + " " +
                                                 e.tile.to_string());
                                 }}) {}
};

TEST(TileStream, AsksForTheRootFirstAndThenEveryWantedTileOnceInItsOrder) {
  TileStream s;
  const Clock::time_point t0{};
  EXPECT_EQ(tiles_of(s.start().requests), std::vector<TileId>{kStreamRoot});
  EXPECT_TRUE(s.start().requests.empty());  // on its way already
  const auto w = want({kStreamRoot, kA, kC});
  const StreamStep step = s.frame(1, t0, &w);
  EXPECT_EQ(tiles_of(step.requests), (std::vector<TileId>{kA, kC}));
  EXPECT_TRUE(step.cancels.empty());
  EXPECT_EQ(s.pending(), 3u);
  // The same list next frame, or no new list: nothing more.
  EXPECT_TRUE(s.frame(2, t0, &w).requests.empty());
  EXPECT_TRUE(s.frame(3, t0, nullptr).requests.empty());
  EXPECT_EQ(s.missing(), 3u);
}

TEST(TileStream, CancelsWhatIsOnItsWayAndNoLongerWantedButNeverTheRoot) {
  TileStream s;
  const Clock::time_point t0{};
  s.start();
  const auto first = want({kA, kB, kC});
  s.frame(1, t0, &first);
  const auto second = want({kB, kD});
  const StreamStep step = s.frame(2, t0, &second);
  EXPECT_EQ(step.cancels, (std::vector<TileId>{kA, kC}));  // sorted
  EXPECT_EQ(tiles_of(step.requests), std::vector<TileId>{kD});
  EXPECT_EQ(s.state(kA), TileStream::State::none);
  EXPECT_EQ(s.state(kStreamRoot), TileStream::State::pending);
  EXPECT_EQ(s.pending(), 3u);  // root, B, D
  // Wanted again: asked for again.
  EXPECT_EQ(tiles_of(s.frame(3, t0, &first).requests), (std::vector<TileId>{kA, kC}));
}

TEST(TileStream, PlacedTilesAreResidentAbsentOnesResolvedAndNeitherIsAskedForAgain) {
  Traced t;
  const Clock::time_point t0{};
  t.stream.start();
  const auto w = want({kStreamRoot, kA, kB});
  t.stream.frame(1, t0, &w);
  ASSERT_TRUE(t.stream.place(kStreamRoot));
  ASSERT_TRUE(t.stream.place(kA));
  t.stream.absent(kB);
  EXPECT_EQ(t.stream.state(kStreamRoot), TileStream::State::resident);
  EXPECT_EQ(t.stream.state(kB), TileStream::State::absent);
  EXPECT_EQ(t.stream.pending(), 0u);
  EXPECT_EQ(t.stream.missing(), 0u);
  EXPECT_EQ(t.stream.absent_count(), 1u);
  EXPECT_TRUE(t.stream.frame(2, t0 + 1h, &w).requests.empty());
  EXPECT_FALSE(t.stream.place(kA));  // resident already: no second slot
  EXPECT_EQ(t.log, (std::vector<std::string>{"request 0/0/0", "request 1/0/0", "request 1/1/0",
                                             "placed 0/0/0", "placed 1/0/0", "absent 1/1/0"}));
}

TEST(TileStream, AFailedTileWaitsABackoffThatDoublesUpToItsCap) {
  TileStreamOptions o;
  o.backoff = 250ms;
  o.max_backoff = 1000ms;
  TileStream s(o);
  const Clock::time_point t0{};
  const auto w = want({kA});
  ASSERT_EQ(s.frame(1, t0, &w).requests.size(), 1u);
  // Failures at t0, then at each retry: waits of 250, 500, 1000, 1000 ms.
  Clock::time_point now = t0;
  for (const auto wait : {250ms, 500ms, 1000ms, 1000ms}) {
    s.failed(kA, now);
    EXPECT_EQ(s.state(kA), TileStream::State::backing_off);
    EXPECT_EQ(s.pending(), 0u);
    EXPECT_TRUE(s.frame(2, now + wait - 1ms, nullptr).requests.empty()) << wait.count();
    now += wait;
    EXPECT_EQ(s.frame(3, now, nullptr).requests.size(), 1u) << wait.count();
  }
  EXPECT_EQ(s.failure_count(), 4u);
  // A success ends the back-off.
  ASSERT_TRUE(s.place(kA));
  EXPECT_EQ(s.state(kA), TileStream::State::resident);
}

TEST(TileStream, ResidencyFollowsTheSlotCacheAndTheRootIsPinned) {
  Traced t({.capacity = 2, .keep_frames = 1});
  const Clock::time_point t0{};
  t.stream.start();
  const auto first = want({kStreamRoot, kA});
  t.stream.frame(1, t0, &first);
  ASSERT_TRUE(t.stream.place(kStreamRoot));
  ASSERT_TRUE(t.stream.place(kA));
  // Frame 2 wants B instead of A: A (unseen this frame) gives B its slot, the root stays.
  const auto second = want({kStreamRoot, kB});
  t.stream.frame(2, t0, &second);
  auto got = t.stream.place(kB);
  ASSERT_TRUE(got);
  ASSERT_TRUE(got->evicted);
  EXPECT_EQ(*got->evicted, kA);
  EXPECT_EQ(t.stream.state(kA), TileStream::State::none);
  // Frame 3 wants A and B: B is used this frame, the root is pinned, so A is refused and asked
  // for again at the next frame.
  const auto both = want({kStreamRoot, kA, kB});
  EXPECT_EQ(tiles_of(t.stream.frame(3, t0, &both).requests), std::vector<TileId>{kA});
  EXPECT_FALSE(t.stream.place(kA));
  EXPECT_EQ(tiles_of(t.stream.frame(4, t0, nullptr).requests), std::vector<TileId>{kA});
  EXPECT_EQ(t.log.back(), "request 1/0/0");
  EXPECT_EQ(t.log[t.log.size() - 2], "refused 1/0/0");
  EXPECT_EQ(t.stream.slots().stats().pinned, 1u);
}

TEST(TileStream, ADroppedRequestIsAskedForAgainAndALateArrivalIsStillPlaced) {
  TileStream s;
  const Clock::time_point t0{};
  const auto w = want({kA, kB});
  s.frame(1, t0, &w);
  s.drop(kA);  // the client gave up on it
  EXPECT_EQ(s.pending(), 1u);
  EXPECT_EQ(tiles_of(s.frame(2, t0, nullptr).requests), std::vector<TileId>{kA});
  // B is cancelled, then its answer comes anyway: it is placed (it was paid for).
  const auto only_a = want({kA});
  EXPECT_EQ(s.frame(3, t0, &only_a).cancels, std::vector<TileId>{kB});
  EXPECT_TRUE(s.place(kB));
  EXPECT_EQ(s.pending(), 1u);
}

TEST(TileStream, AWantedListBeyondTheSlotsRaisesTheMipBias) {
  TileStream s(TileStreamOptions{.slots = {.capacity = 10, .keep_frames = 1}, .max_bias = 2});
  const Clock::time_point t0{};
  std::vector<TileRequest> many;
  for (std::uint32_t x = 0; x < 12; ++x) many.push_back(TileRequest{TileId{4, x, 0}, 1, true});
  EXPECT_EQ(s.bias(), 0.0);
  s.frame(1, t0, nullptr);  // no new list: nothing to judge by
  EXPECT_EQ(s.bias(), 0.0);
  s.frame(2, t0, &many);
  EXPECT_EQ(s.bias(), 1.0);
  s.frame(3, t0, &many);
  s.frame(4, t0, &many);
  EXPECT_EQ(s.bias(), 2.0);  // its cap
}

}  // namespace
}  // namespace vts::renderer
