#include "vts/renderer/tile_stream.hpp"

#include <algorithm>
#include <limits>

namespace vts::renderer {

const char* stream_event_name(StreamEvent::Kind kind) {
  switch (kind) {
    case StreamEvent::Kind::request:
      return "request";
    case StreamEvent::Kind::cancel:
      return "cancel";
    case StreamEvent::Kind::placed:
      return "placed";
    case StreamEvent::Kind::refused:
      return "refused";
    case StreamEvent::Kind::evicted:
      return "evicted";
    case StreamEvent::Kind::absent:
      return "absent";
    case StreamEvent::Kind::failed:
      return "failed";
  }
  return "unknown";
}

TileStream::TileStream(TileStreamOptions options)
    : options_(std::move(options)),
      slots_(options_.slots),
      bias_({.capacity = options_.slots.capacity, .max_bias = options_.max_bias}) {}

void TileStream::note(StreamEvent::Kind kind, TileId tile) const {
  if (options_.trace) options_.trace(StreamEvent{kind, tile});
}

StreamStep TileStream::start() {
  StreamStep step;
  const TileId root{};
  if (state(root) != State::none) return step;
  entries_[tile_key(root)].state = State::pending;
  pending_.insert(tile_key(root));
  step.requests.push_back(
      TileRequest{root, std::numeric_limits<std::uint32_t>::max(), /*direct=*/false});
  note(StreamEvent::Kind::request, root);
  return step;
}

StreamStep TileStream::frame(std::uint64_t frame, Clock::time_point now,
                             const std::vector<TileRequest>* wanted) {
  StreamStep step;
  slots_.begin_frame(frame);
  if (wanted) {
    wanted_ = *wanted;
    bias_.update(wanted_.size());
    wanted_keys_.clear();
    for (const TileRequest& r : wanted_) wanted_keys_.insert(tile_key(r.tile));
    // On their way and no longer wanted: cancelled (never the root).
    const std::uint64_t root = tile_key(TileId{});
    for (auto it = pending_.begin(); it != pending_.end();) {
      if (*it == root || wanted_keys_.count(*it)) {
        ++it;
        continue;
      }
      const TileId t = tile_from_key(*it);
      step.cancels.push_back(t);
      note(StreamEvent::Kind::cancel, t);
      entries_.erase(*it);
      it = pending_.erase(it);
    }
    // The cancellations in a stable order (the map's is not), so traces compare.
    std::sort(step.cancels.begin(), step.cancels.end());
  }
  for (const TileRequest& r : wanted_) {
    if (slots_.slot_of(r.tile)) continue;
    const std::uint64_t key = tile_key(r.tile);
    Entry& e = entries_[key];
    if (e.state == State::pending || e.state == State::absent) continue;
    if (e.state == State::backing_off && e.retry_at > now) continue;
    e.state = State::pending;
    pending_.insert(key);
    step.requests.push_back(r);
    note(StreamEvent::Kind::request, r.tile);
  }
  for (const TileRequest& r : wanted_) slots_.touch(r.tile);
  return step;
}

std::optional<SlotCache::Acquired> TileStream::place(TileId tile) {
  const std::uint64_t key = tile_key(tile);
  if (slots_.slot_of(tile)) return std::nullopt;
  // A tile may arrive after its cancellation (it was on its way): it is placed all the same.
  entries_.erase(key);
  pending_.erase(key);
  auto got = slots_.acquire(tile);
  if (!got) {
    note(StreamEvent::Kind::refused, tile);
    return std::nullopt;
  }
  if (got->evicted) note(StreamEvent::Kind::evicted, *got->evicted);
  if (tile == TileId{}) slots_.pin(tile);
  note(StreamEvent::Kind::placed, tile);
  return got;
}

void TileStream::absent(TileId tile) {
  Entry& e = entries_[tile_key(tile)];
  if (e.state == State::absent) return;
  pending_.erase(tile_key(tile));
  e.state = State::absent;
  ++absent_count_;
  note(StreamEvent::Kind::absent, tile);
}

void TileStream::failed(TileId tile, Clock::time_point now) {
  Entry& e = entries_[tile_key(tile)];
  pending_.erase(tile_key(tile));
  e.state = State::backing_off;
  e.failures = std::min(e.failures + 1, 30);
  auto wait = options_.backoff;
  for (int i = 1; i < e.failures && wait < options_.max_backoff; ++i) wait *= 2;
  e.retry_at = now + std::min(wait, options_.max_backoff);
  ++failure_count_;
  note(StreamEvent::Kind::failed, tile);
}

void TileStream::drop(TileId tile) {
  const std::uint64_t key = tile_key(tile);
  if (pending_.erase(key)) entries_.erase(key);
}

TileStream::State TileStream::state(TileId tile) const {
  if (slots_.slot_of(tile)) return State::resident;
  auto it = entries_.find(tile_key(tile));
  return it == entries_.end() ? State::none : it->second.state;
}

std::uint32_t TileStream::missing() const {
  std::uint32_t n = 0;
  for (const TileRequest& r : wanted_) {
    const State s = state(r.tile);
    if (s != State::resident && s != State::absent) ++n;
  }
  return n;
}

}  // namespace vts::renderer
