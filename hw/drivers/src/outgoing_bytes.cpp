// OutgoingBytes: see outgoing_bytes.hpp.
#include <tessera/drivers/outgoing_bytes.hpp>

#include <algorithm>

namespace tessera::drivers {

void OutgoingBytes::queue(std::int64_t due_ns, std::string bytes) {
  const auto at = std::upper_bound(pending_.begin(), pending_.end(), due_ns,
                                   [](std::int64_t t, const Pending& p) { return t < p.due_ns; });
  pending_.insert(at, {due_ns, std::move(bytes)});
}

void OutgoingBytes::append(std::int64_t due_ns, std::string bytes) {
  pending_.push_back(
      {pending_.empty() ? due_ns : std::max(due_ns, pending_.back().due_ns), std::move(bytes)});
}

std::string OutgoingBytes::take(std::int64_t now_ns) {
  std::string out;
  std::size_t k = 0;
  while (k < pending_.size() && pending_[k].due_ns <= now_ns) out += pending_[k++].bytes;
  pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(k));
  return out;
}

std::string OutgoingBytes::take(std::int64_t now_ns, int& baud) {
  std::string out = take(now_ns);
  if (baud_after_ > 0 && pending_.empty()) {
    baud = baud_after_;
    baud_after_ = 0;
  }
  return out;
}

std::optional<std::int64_t> OutgoingBytes::nextDue() const {
  if (pending_.empty()) return std::nullopt;
  return pending_.front().due_ns;
}

void OutgoingBytes::clear() {
  pending_.clear();
  baud_after_ = 0;
}

}  // namespace tessera::drivers
