// Mailbox policies: how a subscription behaves when its consumer falls behind.
//   keep_latest(n): sensor streams. At most n messages wait; a new one evicts the oldest, and the
//                   eviction is counted as a drop.
//   reliable(n):    state that must not be lost (submaps, constraints, goals). At most n wait; a
//                   publisher that finds the mailbox full waits (or runs the consumer itself)
//                   until there is room. Never drops.
#pragma once

#include <cstddef>
#include <string>

namespace tessera {

struct MailboxPolicy {
  enum class Kind { kKeepLatest, kReliable };
  Kind kind = Kind::kKeepLatest;
  std::size_t capacity = 1;
  /// An observer's subscription (viewer, monitor): the topic need not have a publisher.
  bool optional = false;

  static MailboxPolicy keepLatest(std::size_t n) { return {Kind::kKeepLatest, n < 1 ? 1 : n}; }
  static MailboxPolicy reliable(std::size_t n = 64) { return {Kind::kReliable, n < 1 ? 1 : n}; }
  MailboxPolicy asOptional() const {
    MailboxPolicy p = *this;
    p.optional = true;
    return p;
  }
  std::string describe() const;
};

}  // namespace tessera
