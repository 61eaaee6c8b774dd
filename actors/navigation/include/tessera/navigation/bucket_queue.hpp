// MonotoneBucketQueue: the open list of GridPlanner (docs/algorithms.md#global-planning).
//
// A priority queue of integer keys for searches whose keys never drop below the last popped
// one: Dijkstra, and A* with a consistent heuristic, on integer step costs. One bucket per key
// in a ring of `span` + 1 buckets (a power of two), a bitmap of the non-empty ones: push and pop
// are O(1) plus a scan of the bitmap for the next non-empty bucket. Pops come in key order;
// equal keys last in, first out (in A* that favours the cells just reached, i.e. deeper ones).
// The first push after clear() / reset() sets the base key; from then on a push below the last
// popped key (or the base, before any pop), or more than `span` above it, is a caller's bug
// and throws std::invalid_argument. Memory is kept between uses (clear(), reset()).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tessera::navigation {

class MonotoneBucketQueue {
 public:
  struct Entry {
    std::int64_t key = 0;
    std::int32_t value = 0;  ///< the caller's payload (a cell index)
  };

  /// A queue for keys at most `span` (>= 0, < 2^24) above the last popped one.
  explicit MonotoneBucketQueue(std::int64_t span = 0);

  /// Empties the queue and sets the span; throws std::invalid_argument on a bad span.
  void reset(std::int64_t span);
  void clear();  ///< empties the queue, keeps its memory

  /// Adds (key, value); the first push after clear() sets the base key.
  void push(std::int64_t key, std::int32_t value) {
    if (fresh_) {
      current_ = key;
      fresh_ = false;
    }
    if (key < current_ || key - current_ > span_) refuse(key);
    const auto slot = static_cast<std::size_t>(key & mask_);
    if (ring_[slot].empty()) bits_[slot >> 6] |= std::uint64_t{1} << (slot & 63);
    ring_[slot].push_back(value);
    ++size_;
  }
  Entry pop();  ///< the entry with the smallest key; the queue must not be empty
  bool empty() const { return size_ == 0; }
  std::size_t size() const { return size_; }
  std::int64_t span() const { return span_; }

 private:
  [[noreturn]] void refuse(std::int64_t key) const;

  std::int64_t span_ = 0;
  std::int64_t mask_ = 0;                        ///< ring size - 1
  std::vector<std::vector<std::int32_t>> ring_;  ///< bucket of key k at k & mask_
  std::vector<std::uint64_t> bits_;              ///< non-empty buckets
  std::int64_t current_ = 0;                     ///< the last popped key (or the base)
  std::size_t size_ = 0;
  bool fresh_ = true;  ///< nothing pushed since clear()
};

}  // namespace tessera::navigation
