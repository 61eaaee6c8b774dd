// BaseControllerActor ("base_controller"): the last stage before the motors. It takes velocity
// commands (from the navigator, a teleoperation, a script), keeps them within the base's speed
// and acceleration limits, and sends the base a command at a steady rate; when commands stop
// coming (timeout_s) it brakes to a standstill within the same limits, and a non-finite command
// never reaches the base (it counts as a stop). A thin actor over BaseCommandFilter.
//
// Subscribes: cmd_vel   msg::Twist keep_latest(1): vx [m/s] forward, omega [rad/s]; vy ignored
// Publishes:  base_cmd  msg::Twist at rate_hz, frame base_link: what the base should do now
// Units: metres, radians, seconds; the runtime's clock (simulated in the simulator).
#pragma once

#include <tessera/messages/types.hpp>
#include <tessera/navigation/base_command_filter.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>

namespace tessera::navigation {

struct BaseControllerOptions {
  BaseLimitsOptions limits;
  double rate_hz = 50;
  double timeout_s = 0.3;

  template <class V>
  void visit(V& v) {
    v("limits", limits, "the base's speed and acceleration limits");
    v("rate_hz", rate_hz, "[Hz] rate of base_cmd");
    v("timeout_s", timeout_s, "[s] without a new cmd_vel for this long the base brakes to a stop");
  }
};

class BaseControllerActor final : public Actor {
 public:
  /// Throws ConfigError naming the bad option.
  explicit BaseControllerActor(BaseControllerOptions options);
  void configure(ActorContext& ctx) override;
  /// commands, nonfinite_commands, clamped_commands, timeouts (times the watchdog engaged),
  /// base_commands published.
  void summarize(Summary& out) const override;

 private:
  void tick();

  BaseControllerOptions options_;
  BaseCommandFilter filter_;
  ActorContext* ctx_ = nullptr;
  Publisher<msg::Twist> pub_;
  BaseCommandFilter::Twist wanted_;
  Nanos last_command_ = -1;
  bool timed_out_ = true;
  std::uint64_t commands_ = 0, nonfinite_ = 0, clamped_ = 0, timeouts_ = 0, published_ = 0;
};

}  // namespace tessera::navigation
