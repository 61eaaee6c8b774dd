#include <tessera/navigation/base_command_filter.hpp>

#include <tessera/config/config_check.hpp>

#include <algorithm>
#include <cmath>

namespace tessera::navigation {

void BaseLimitsOptions::validate() const {
  ConfigCheck()
      .positive("max_speed", max_speed)
      .nonNegative("max_reverse", max_reverse)
      .positive("max_turn_rate", max_turn_rate)
      .positive("acceleration", acceleration)
      .positive("turn_acceleration", turn_acceleration)
      .throwIfBad("base limits");
}

BaseCommandFilter::BaseCommandFilter(const BaseLimitsOptions& limits) : limits_(limits) {
  limits_.validate();
}

BaseCommandFilter::Twist BaseCommandFilter::step(const Twist& wanted, double dt) {
  const double v =
      std::isfinite(wanted.v) ? std::clamp(wanted.v, -limits_.max_reverse, limits_.max_speed) : 0.0;
  const double w = std::isfinite(wanted.w)
                       ? std::clamp(wanted.w, -limits_.max_turn_rate, limits_.max_turn_rate)
                       : 0.0;
  const double h = std::isfinite(dt) && dt > 0 ? dt : 0.0;
  const double dv = limits_.acceleration * h, dw = limits_.turn_acceleration * h;
  last_.v += std::clamp(v - last_.v, -dv, dv);
  last_.w += std::clamp(w - last_.w, -dw, dw);
  return last_;
}

}  // namespace tessera::navigation
