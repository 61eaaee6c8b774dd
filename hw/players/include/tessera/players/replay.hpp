// Shared pieces of the dataset players (carmen_player, urg_player): mapping dataset time onto the
// runtime clock, and small pose helpers.
//
// Time: the runtime's simulated clock starts at 0 and a periodic timer of any actor would have
// to fire once per period to get from 0 to an absolute dataset time such as 976052857 s, so
// players never schedule at absolute dataset times. They schedule record k at
//   runtime_start + (t_k - t_0)          (t_0 = time of the first published record)
// and, by default, stamp messages with the dataset's own absolute time in ns (int64 ns covers
// ±292 years, so 2001 epoch times fit), so trajectories written from them carry the dataset's
// timestamps. With relative_stamps, stamps are the runtime times instead.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/runtime/clock.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <optional>

namespace tessera::players {

// Dataset seconds -> ns, rounded to whole microseconds (the resolution of CARMEN and URG logs;
// it also avoids writing double-rounding noise such as .338881969 into trajectory files).
// nullopt when the time is not finite or outside the int64 ns range.
inline std::optional<Nanos> datasetSecondsToNanos(double t) {
  if (!std::isfinite(t) || std::abs(t) > 9.0e9) return std::nullopt;
  const double whole = std::floor(t);
  const auto us = static_cast<Nanos>(std::llround((t - whole) * 1e6));
  return static_cast<Nanos>(whole) * kNanosPerSecond + us * 1000;
}

// Maps dataset time to runtime time; the first call to start() fixes the origin.
class ReplayTimeline {
 public:
  void start(Nanos dataset_ns, Nanos runtime_now) {
    dataset0_ = dataset_ns;
    runtime0_ = runtime_now;
    started_ = true;
  }
  bool started() const { return started_; }
  // When a record stamped `dataset_ns` is due on the runtime clock (never before the origin).
  Nanos due(Nanos dataset_ns) const {
    return dataset_ns <= dataset0_ ? runtime0_ : runtime0_ + (dataset_ns - dataset0_);
  }
  Nanos stamp(Nanos dataset_ns, bool relative) const {
    return relative ? due(dataset_ns) : dataset_ns;
  }
  Nanos origin() const { return dataset0_; }

 private:
  Nanos dataset0_ = 0, runtime0_ = 0;
  bool started_ = false;
};

// Where a player is in its input: the record read but not yet published, and counters.
template <class Pending>  // Pending has a `Nanos stamp` (dataset time)
struct ReplayState {
  ReplayTimeline timeline;
  std::optional<Pending> next;
  Nanos last_published = 0;
  std::int64_t reversals = 0;  // records stamped before one already published

  // One scheduling step: publishes every record due at runtime time `now` (equal stamps, or
  // time running backwards, go out together), refilling `next` with read() (returns false at
  // the end of the input). Returns the runtime time of the next step, or nullopt when the
  // input is exhausted or limit() (checked after each record) says to stop.
  template <class Read, class Publish, class Limit>
  std::optional<Nanos> advance(Nanos now, Read&& read, Publish&& publish, Limit&& limit) {
    if (!next && !read()) return std::nullopt;
    if (!timeline.started()) timeline.start(next->stamp, now);
    while (next && timeline.due(next->stamp) <= now) {
      if (next->stamp < last_published) ++reversals;
      publish(*next);
      last_published = std::max(last_published, next->stamp);
      next.reset();
      if (limit() || !read()) return std::nullopt;
    }
    return timeline.due(next->stamp);
  }
};

// Velocity of the body between two poses `dt` seconds apart, in the first pose's frame.
struct BodyVelocity {
  double vx = 0, vy = 0, omega = 0;
};
inline BodyVelocity bodyVelocity(const Pose2& from, const Pose2& to, double dt) {
  if (!(dt > 0)) return {};
  const Pose2 d = between(from, to);
  return {d.x / dt, d.y / dt, d.theta / dt};
}

}  // namespace tessera::players
