// MonotoneBucketQueue: a ring of one bucket per key and a bitmap of the non-empty ones.
#include <tessera/navigation/bucket_queue.hpp>

#include <algorithm>
#include <bit>
#include <stdexcept>
#include <string>

namespace tessera::navigation {

MonotoneBucketQueue::MonotoneBucketQueue(std::int64_t span) {
  reset(span);
}

void MonotoneBucketQueue::reset(std::int64_t span) {
  if (span < 0 || span >= (std::int64_t{1} << 24))
    throw std::invalid_argument("bucket queue: span must be in [0, 2^24), got " +
                                std::to_string(span));
  clear();
  // span + 1 keys are live at once (current_ … current_ + span); at least 64 buckets, so the
  // bitmap has whole words.
  std::int64_t ring = 64;
  while (ring < span + 1) ring *= 2;
  if (ring != mask_ + 1 || ring_.empty()) {
    ring_.assign(static_cast<std::size_t>(ring), {});
    bits_.assign(static_cast<std::size_t>(ring / 64), 0);
    mask_ = ring - 1;
  }
  span_ = span;
}

void MonotoneBucketQueue::clear() {
  if (size_ > 0)
    for (std::size_t w = 0; w < bits_.size(); ++w)
      for (std::uint64_t b = bits_[w]; b != 0; b &= b - 1)
        ring_[w * 64 + static_cast<std::size_t>(std::countr_zero(b))].clear();
  std::fill(bits_.begin(), bits_.end(), 0);
  size_ = 0;
  fresh_ = true;
}

MonotoneBucketQueue::Entry MonotoneBucketQueue::pop() {
  if (size_ == 0) throw std::logic_error("bucket queue: pop from an empty queue");
  // The next non-empty bucket at or after current_, cyclically (all keys lie within the ring).
  const auto words = bits_.size();
  auto slot = static_cast<std::size_t>(current_ & mask_);
  std::size_t w = slot >> 6;
  std::uint64_t b = bits_[w] & (~std::uint64_t{0} << (slot & 63));
  while (b == 0) {
    w = w + 1 == words ? 0 : w + 1;
    b = bits_[w];
  }
  const std::size_t found = w * 64 + static_cast<std::size_t>(std::countr_zero(b));
  current_ += static_cast<std::int64_t>((found - slot) & static_cast<std::size_t>(mask_));
  auto& bucket = ring_[found];
  const Entry e{current_, bucket.back()};
  bucket.pop_back();
  if (bucket.empty()) bits_[found >> 6] &= ~(std::uint64_t{1} << (found & 63));
  --size_;
  return e;
}

void MonotoneBucketQueue::refuse(std::int64_t key) const {
  throw std::invalid_argument("bucket queue: key " + std::to_string(key) + " outside [" +
                              std::to_string(current_) + ", " + std::to_string(current_ + span_) +
                              "] (the last popped key + span)");
}

}  // namespace tessera::navigation
