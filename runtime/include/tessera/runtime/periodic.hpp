// addPeriodicTimer: the "every publish_period_s seconds, 0 = off" timer several actors offer.
#pragma once

#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/clock.hpp>

#include <algorithm>
#include <functional>
#include <utility>

namespace tessera {

/// Calls `callback` every `period_s` seconds of runtime-clock time, the first one period from
/// now; nothing when period_s <= 0 (the option's "off"). Periods round up to at least 1 ns.
inline void addPeriodicTimer(ActorContext& ctx, double period_s, std::function<void()> callback) {
  if (!(period_s > 0)) return;
  const Nanos period = std::max<Nanos>(1, secondsToNanos(period_s));
  ctx.addTimer(period, std::move(callback), period);
}

}  // namespace tessera
