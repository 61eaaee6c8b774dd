#include <tessera/navigation/base_controller_actor.hpp>

#include <tessera/runtime/registry.hpp>

#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::navigation {

namespace {

BaseControllerOptions checked(BaseControllerOptions o) {
  try {
    o.limits.validate();
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("base_controller: option 'limits' ") + e.what());
  }
  if (!(std::isfinite(o.rate_hz) && o.rate_hz > 0 && o.rate_hz <= 1000))
    throw ConfigError("base_controller: option 'rate_hz' must be in (0, 1000], got " +
                      std::to_string(o.rate_hz));
  if (!(std::isfinite(o.timeout_s) && o.timeout_s > 0))
    throw ConfigError("base_controller: option 'timeout_s' must be finite and > 0, got " +
                      std::to_string(o.timeout_s));
  return o;
}

}  // namespace

BaseControllerActor::BaseControllerActor(BaseControllerOptions options)
    : options_(checked(std::move(options))), filter_(options_.limits) {}

void BaseControllerActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.subscribe<msg::Twist>(
      "cmd_vel", MailboxPolicy::keepLatest(1), [this](const Message<msg::Twist>& m) {
        ++commands_;
        const double v = m->getTwist().getVx(), w = m->getTwist().getOmega();
        if (!(std::isfinite(v) && std::isfinite(w))) {
          ++nonfinite_;  // a stop, not a command
          wanted_ = {};
        } else {
          const auto& l = options_.limits;
          if (v > l.max_speed || v < -l.max_reverse || std::abs(w) > l.max_turn_rate) ++clamped_;
          wanted_ = {v, w};
        }
        last_command_ = ctx_->now();
      });
  pub_ = ctx.advertise<msg::Twist>("base_cmd");
  const auto period = static_cast<Nanos>(std::llround(1e9 / options_.rate_hz));
  ctx.addTimer(period, [this] { tick(); });
}

void BaseControllerActor::tick() {
  const Nanos now = ctx_->now();
  const bool timed_out =
      last_command_ < 0 || nanosToSeconds(now - last_command_) > options_.timeout_s;
  if (timed_out && !timed_out_ && last_command_ >= 0) ++timeouts_;
  timed_out_ = timed_out;
  const BaseCommandFilter::Twist out =
      filter_.step(timed_out ? BaseCommandFilter::Twist{} : wanted_, 1.0 / options_.rate_hz);
  auto loan = pub_.loan();
  setHeader(loan->initHeader(), now, "base_link", pub_.nextSeq());
  auto t = loan->initTwist();
  t.setVx(out.v);
  t.setVy(0);
  t.setOmega(out.w);
  pub_.publish(std::move(loan));
  ++published_;
}

void BaseControllerActor::summarize(Summary& out) const {
  out["commands"] = static_cast<std::int64_t>(commands_);
  out["nonfinite_commands"] = static_cast<std::int64_t>(nonfinite_);
  out["clamped_commands"] = static_cast<std::int64_t>(clamped_);
  out["timeouts"] = static_cast<std::int64_t>(timeouts_);
  out["base_commands"] = static_cast<std::int64_t>(published_);
}

TESSERA_REGISTER_ACTOR("base_controller", BaseControllerActor, BaseControllerOptions,
                       "velocity commands within the base's limits at a steady rate; brakes to a "
                       "stop when commands stop (watchdog); NaN never reaches the base");

}  // namespace tessera::navigation
